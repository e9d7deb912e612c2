//! Throughput of faer's matrix products at PoissonNet's paper-preset shapes,
//! alone (no network around them): the ceiling the dense layers can reach
//! on this machine.
//!
//! ```text
//! cargo run --release -p mfm-net --example gemm_peak -- [THREADS...]
//! ```
//! For each thread count (default `1 2`), that many threads each run the
//! products on their own data at once (as the dense layers' row blocks do)
//! and the best of 5 runs is printed, per thread and in total:
//! - `forward`: `[27864, 128] x [128, 128]` with a column-major right-hand
//!   side (the layers' forward and input-gradient products), on contiguous
//!   rows and on every other half row (a complex layer's real or imaginary
//!   part);
//! - `weight gradient`: `[128, 27864] x [27864, 128]` summed over 512-row
//!   chunks (the complex layers' weight gradients), contiguous and strided.
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

const ROWS: usize = 27864;
const WIDTH: usize = 128;

fn best_seconds(mut f: impl FnMut()) -> f64 {
    f();
    (0..5)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// GFLOP/s of each kind of product, run on this thread.
fn rates() -> Vec<(String, f64)> {
    let (n, w) = (ROWS, WIDTH);
    let x: Vec<f32> = (0..n * 2 * w)
        .map(|i| ((i * 7919) % 1000) as f32 * 1e-3)
        .collect();
    let weight: Vec<f32> = (0..w * w).map(|i| ((i * 31) % 100) as f32 * 1e-2).collect();
    let mut y = vec![0f32; n * 2 * w];
    let flops = 2.0 * (n * w * w) as f64;
    let mut out = Vec::new();
    for (layout, stride) in [("contiguous rows", 1), ("half rows", 2)] {
        let t = best_seconds(|| {
            let a = MatRef::from_row_major_slice_with_stride(&x, n, w, stride * w);
            let b = MatRef::from_row_major_slice(&weight, w, w).transpose();
            let c = MatMut::from_row_major_slice_with_stride_mut(&mut y, n, w, stride * w);
            matmul(c, Accum::Replace, a, b, 1.0, Par::Seq);
        });
        out.push((format!("forward, {layout}"), flops / t * 1e-9));
    }
    for (layout, stride) in [("contiguous rows", 1), ("half rows", 2)] {
        let mut d = vec![0f32; w * w];
        let t = best_seconds(|| {
            for c0 in (0..n).step_by(512) {
                let rows = (c0 + 512).min(n) - c0;
                let a = &x[c0 * stride * w..];
                let xm = MatRef::from_row_major_slice_with_stride(a, rows, w, stride * w);
                let gm = xm.transpose();
                let dm = MatMut::from_row_major_slice_mut(&mut d, w, w);
                matmul(dm, Accum::Add, gm, xm, 1.0, Par::Seq);
            }
        });
        out.push((format!("weight gradient, {layout}"), flops / t * 1e-9));
    }
    out
}

fn main() {
    let counts: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("thread counts are positive integers"))
        .collect();
    let counts = if counts.is_empty() {
        vec![1, 2]
    } else {
        counts
    };
    for threads in counts {
        let per_thread: Vec<Vec<(String, f64)>> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..threads.max(1)).map(|_| s.spawn(rates)).collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        println!("{threads} thread(s), GFLOP/s per thread [total]:");
        for (i, (name, _)) in per_thread[0].iter().enumerate() {
            let rates: Vec<f64> = per_thread.iter().map(|r| r[i].1).collect();
            let list: Vec<String> = rates.iter().map(|r| format!("{r:.0}")).collect();
            println!(
                "  {name:<32} {} [{:.0}]",
                list.join(" "),
                rates.iter().sum::<f64>()
            );
        }
    }
}
