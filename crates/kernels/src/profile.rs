//! A coarse profiler for the network's sections: wall-clock and process CPU
//! time per named section.
//!
//! The timers exist only with the crate's `profile` feature ([`AVAILABLE`];
//! `mfm-net`'s `bench` feature turns it on). Without it every section
//! compiles to nothing and [`set_enabled`] records nothing. With it the
//! profiler is still off until [`set_enabled`] (one relaxed atomic load per
//! section when off); when on, [`section`] timers accumulate wall seconds,
//! process CPU seconds (all threads; on a machine shared with other busy
//! processes this is the steadier measure of the work) and call counts per
//! name; the benchmark (`mfm_net::bench`) turns it on to report where a
//! training step spends its time. On the CPU torch operations are synchronous, so a section's time is
//! the time of its operations; on a GPU it only measures the launch unless
//! the section synchronizes.
//!
//! Sections nest freely (each reports its own inclusive time). Every custom
//! autograd node ([`crate::autograd::apply_custom`]) reports its forward as
//! `fn:<name>` and its backward as `fn:<name>^T`; linear operators
//! ([`crate::autograd::apply_linear`], themselves custom nodes) also report
//! as `op:<name>` (`op:<name>^T` for the adjoint), so an operator's time
//! appears under both names. The dense layers add `linear.dx`,
//! `linear.dw <o>x<k>`, `linear.bias`, `linear.db`, `complex.dz` and
//! `complex.dw` inside their nodes.

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

static ENABLED: AtomicBool = AtomicBool::new(false);
static TOTALS: Mutex<BTreeMap<String, SectionTotal>> = Mutex::new(BTreeMap::new());

/// Accumulated time of one section.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SectionTotal {
    /// Wall-clock seconds.
    pub wall: f64,
    /// Process CPU seconds (all threads).
    pub cpu: f64,
    /// Number of times the section ran.
    pub calls: u64,
}

/// Whether this build has the section timers (the crate's `profile`
/// feature).
pub const AVAILABLE: bool = cfg!(feature = "profile");

/// Turns the profiler on or off (totals are kept; see [`reset`]). Without
/// the `profile` feature ([`AVAILABLE`]) it stays off.
pub fn set_enabled(on: bool) {
    ENABLED.store(on && AVAILABLE, Ordering::Relaxed);
}

/// Whether the profiler is on (always `false` without the `profile`
/// feature, so the compiler removes every section).
pub fn enabled() -> bool {
    AVAILABLE && ENABLED.load(Ordering::Relaxed)
}

/// Clears the accumulated totals.
pub fn reset() {
    if let Ok(mut t) = TOTALS.lock() {
        t.clear();
    }
}

/// Accumulated totals by section name, sorted by name.
pub fn totals() -> Vec<(String, SectionTotal)> {
    TOTALS
        .lock()
        .map(|t| t.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
        .unwrap_or_default()
}

/// Adds one run of `wall` / `cpu` seconds to the section `name`.
pub fn record(name: &str, wall: f64, cpu: f64) {
    if let Ok(mut t) = TOTALS.lock() {
        let e = t.entry(name.to_owned()).or_default();
        e.wall += wall;
        e.cpu += cpu;
        e.calls += 1;
    }
}

/// A running section; records its time when dropped (only if the profiler
/// was on when it started).
#[derive(Debug)]
pub struct Section {
    start: Option<(String, Instant, f64)>,
}

impl Drop for Section {
    fn drop(&mut self) {
        if let Some((name, start, cpu)) = self.start.take() {
            record(
                &name,
                start.elapsed().as_secs_f64(),
                process_cpu_seconds() - cpu,
            );
        }
    }
}

/// Starts timing the section `name` (a no-op when the profiler is off).
pub fn section(name: impl Into<String>) -> Section {
    Section {
        start: enabled().then(|| (name.into(), Instant::now(), process_cpu_seconds())),
    }
}

/// Times `f` as the section `name`.
pub fn timed<R>(name: &str, f: impl FnOnce() -> R) -> R {
    let _s = section(name);
    f()
}

/// CPU time used by this process so far (all threads), in seconds; 0 where
/// the platform offers no process clock.
pub fn process_cpu_seconds() -> f64 {
    #[cfg(target_os = "linux")]
    {
        #[repr(C)]
        struct Timespec {
            tv_sec: i64,
            tv_nsec: i64,
        }
        const CLOCK_PROCESS_CPUTIME_ID: i32 = 2;
        unsafe extern "C" {
            fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
        }
        let mut ts = Timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime writes one timespec.
        if unsafe { clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9;
        }
        0.0
    }
    #[cfg(not(target_os = "linux"))]
    {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_record_only_when_built_in_and_on() {
        set_enabled(false);
        drop(section("profile-test.off"));
        set_enabled(true);
        assert_eq!(enabled(), AVAILABLE);
        drop(section("profile-test.on"));
        timed("profile-test.on", || ());
        set_enabled(false);
        let totals = totals();
        let calls = |name: &str| totals.iter().find(|(n, _)| n == name).map(|(_, t)| t.calls);
        assert_eq!(calls("profile-test.off"), None);
        assert_eq!(calls("profile-test.on"), AVAILABLE.then_some(2));
    }
}
