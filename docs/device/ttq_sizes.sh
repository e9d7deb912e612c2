#!/usr/bin/env bash
# The GPU rows of docs/BENCHMARKS.md ("Time to quality"): the GMM blob
# experiment at three network sizes on one GPU, three runs sharing it, each
# stopped after TRAIN_SECONDS and its kept checkpoints sampled (32, seed 7)
# and evaluated on the test mesh. Run from a folder holding an `mfm` built
# against the machine's libtorch (BENCHMARKS, "On a GPU"); results in
# $OUT/results.tgz. Usage: ttq_sizes.sh [TRAIN_SECONDS] [cuda|cpu]
set -u
T=${1:-300}; DEV=${2:-cuda}
D=$(cd "$(dirname "$0")" && pwd)
export LD_LIBRARY_PATH=$(python3 -c 'import torch,os;print(os.path.dirname(torch.__file__))')/lib
M=$D/mfm
R=$OUT/r; mkdir -p $R
$M --version || exit 3
nvidia-smi -L || true
W=/tmp/w; rm -rf $W; mkdir -p $W
$M dataset gmm --out $W/data --n 1000 --reference 100 --seed 0 > $R/dataset.txt 2>&1 || { cat $R/dataset.txt; exit 4; }
mk() { # name width blocks layers threads
cat > $W/$1.toml <<T2
[model]
preset = "small"
width = $2
blocks = $3
vector_layers = $4
[train]
steps = 10000000
batch = 4
lr = 2e-3
lr_schedule = { milestones = [[2000, 5e-4]] }
checkpoint_every = 500
log_every = 100
keep_at = [100, 200, 500, 1000, 2000, 5000, 10000, 20000, 50000]
ema = 0.999
threads = $5
device = "$DEV"
T2
}
mk W32K3-h200 32 3 3 4
mk W64K4-h200 64 4 3 5
mk W128K5-h200 128 5 3 6
for v in W32K3-h200 W64K4-h200 W128K5-h200; do
  # --foreground: one SIGINT to mfm (without it the process group gets a
  # second one, and a second signal ends training without its checkpoint)
  timeout --foreground -s INT $T $M train --config $W/$v.toml --dataset $W/data/train --out $W/$v/run --quiet > $R/$v.train.txt 2>&1 &
done
sleep 20; nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv; tail -n 2 $W/*/run/train_log.csv
wait
ev() { # variant
  v=$1; mkdir -p $R/$v
  cp $W/$v/run/train_log.csv $W/$v/run/config.toml $R/$v/
  for c in $W/$v/run/checkpoints/step-*; do
    s=$((10#${c##*step-}))
    case " 100 200 500 1000 2000 5000 10000 20000 50000 " in *" $s "*) ;; *) [ "$c" = "$(ls -d $W/$v/run/checkpoints/step-* | tail -1)" ] || continue;; esac
    mkdir -p $R/$v/step-$s; cp $c/state.json $R/$v/step-$s/
    $M sample --run $W/$v/run --mesh $W/data/reference/mesh.ply --n 32 --seed 7 --out $W/$v/s$s --ply 0 --step $s --device $DEV >> $R/$v.eval.txt 2>&1 \
      && $M eval --samples $W/$v/s$s/samples.npy --reference $W/data/reference --out $R/$v/step-$s/eval.json --png $R/$v/step-$s/eval.png >> $R/$v.eval.txt 2>&1 \
      || echo "step $s failed" >> $R/$v.eval.txt
  done
}
for v in W32K3-h200 W64K4-h200 W128K5-h200; do ev $v & done
wait
cd $OUT && tar czf results.tgz r && rm -rf r
ls -la $OUT
