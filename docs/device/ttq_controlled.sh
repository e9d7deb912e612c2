#!/usr/bin/env bash
# The GPU rows of docs/BENCHMARKS.md ("Training beyond the paper"): three
# controlled W32 K3 runs of 3000 steps on one GPU (no input-gradient
# residual in the NJF head, 16,000 training signals, weight average
# 0.9999), sampled and evaluated like ttq_sizes.sh. Same setup as that one.
set -u
D=$(cd "$(dirname "$0")" && pwd)
export LD_LIBRARY_PATH=$(python3 -c 'import torch,os;print(os.path.dirname(torch.__file__))')/lib
M=$D/mfm; R=$OUT/r; mkdir -p $R; W=/tmp/w; rm -rf $W; mkdir -p $W
$M dataset gmm --out $W/data --n 1000 --reference 100 --seed 0 > $R/dataset.txt 2>&1 || exit 4
$M dataset gmm --out $W/data16k --n 16000 --reference 100 --seed 0 >> $R/dataset.txt 2>&1 || exit 5
mk() { # name extra-model extra-train
cat > $W/$1.toml <<T2
[model]
preset = "small"
width = 32
blocks = 3
vector_layers = 3
$2
[train]
steps = 3000
batch = 4
lr = 2e-3
lr_schedule = { milestones = [[2000, 5e-4]] }
checkpoint_every = 500
log_every = 100
keep_at = [1000]
ema = ${3:-0.999}
threads = 4
device = "cuda"
T2
}
mk G-noNJFres 'head = "njf_no_input_gradient"'
mk G-16k ''
mk G-ema9999 '' 0.9999
for v in G-noNJFres G-16k G-ema9999; do
  ds=$W/data/train; [ $v = G-16k ] && ds=$W/data16k/train
  timeout --foreground -s INT 210 $M train --config $W/$v.toml --dataset $ds --out $W/$v/run --quiet > $R/$v.train.txt 2>&1 &
done
wait
ev() {
  v=$1; mkdir -p $R/$v; cp $W/$v/run/train_log.csv $W/$v/run/config.toml $R/$v/
  for c in $W/$v/run/checkpoints/step-*; do
    s=$((10#${c##*step-}))
    [ $s = 1000 ] || [ "$c" = "$(ls -d $W/$v/run/checkpoints/step-* | tail -1)" ] || continue
    mkdir -p $R/$v/step-$s; cp $c/state.json $R/$v/step-$s/
    $M sample --run $W/$v/run --mesh $W/data/reference/mesh.ply --n 32 --seed 7 --out $W/$v/s$s --ply 0 --step $s --device cuda >> $R/$v.eval.txt 2>&1 \
      && $M eval --samples $W/$v/s$s/samples.npy --reference $W/data/reference --out $R/$v/step-$s/eval.json --png $R/$v/step-$s/eval.png >> $R/$v.eval.txt 2>&1 \
      && cp $W/$v/s$s/samples.png $R/$v/step-$s/samples.png || echo "step $s failed" >> $R/$v.eval.txt
  done
}
for v in G-noNJFres G-16k G-ema9999; do ev $v & done
wait
cd $OUT && tar czf results.tgz r && rm -rf r
