#!/usr/bin/env bash
# The one prepared device check: everything the accelerator issue asks to
# measure on a GPU, in one run under about 8 minutes, each step under its own timeout, every log
# under $OUT, ending in one markdown table (experiments/gpu_check_table.py; also $OUT/table.md).
#
#   run on the GPU machine, from the repository root, with .whl/ carried along, the wheels its
#   image lacks (it brings jax + CUDA, flax, optax, numpy; not flax 0.12.6, which fails on jax
#   >= 0.11), downloaded beforehand on a machine with the network:
#       python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#         --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux2014_x86_64 \
#         -d .whl mujoco==3.17.0 mujoco-mjx==3.17.0 brax==0.14.2 tensorboardX==2.6.5 glfw \
#         pyopengl websockets trimesh ml-collections jaxopt
#       bash experiments/gpu_check.sh
#   on a CPU with tiny sizes (tests/test_gpu_check.py does this; no install):
#       GPU_CHECK_SIZE=tiny GPU_CHECK_INSTALL=0 OUT=/tmp/out bash experiments/gpu_check.sh
#
# Steps, in this order (name: what; its timeout in s at full size):
#   bench       dpc-mjx bench at 4,096 and 32,768 envs, one env step per call        (150)
#   bench_mpc   experiments/bench_mpc.py: the env step with the MPC against the QP,
#               MJX, 4,096 envs (issue 55's cost on a GPU)                           (150)
#   train_cold  default dpc-mjx train --device gpu, empty compilation cache           (180)
#   train_warm  the same again into another run folder, the cache now warm            (120)
#   eval_cold   dpc-mjx eval: 4 controllers x 1,024 episodes of 20 s (shipped export) (120)
#   eval_warm   the same again, warm cache                                            (90)
#   sac         --recipe paper: its SAC stage for a fixed budget of env steps         (240)
#   bench_scan  bench at 16,384 with 20 env steps per call (the per-call floor)       (120)
#   bench_cmdbuf  bench_scan under XLA's GPU command buffers for loops/conditionals   (120)
# A step is skipped when less than 20 s of the whole budget ($GPU_CHECK_BUDGET, 540 s) is
# left; its timeout is cut to what is left.
set -u
OUT=${OUT:?OUT must name the folder for the logs}
SIZE=${GPU_CHECK_SIZE:-full}
PY=${PYTHON:-python3}
mkdir -p "$OUT"
START=$(date +%s)
BUDGET=${GPU_CHECK_BUDGET:-540}
export PYTHONUNBUFFERED=1
CACHE=$(mktemp -d /tmp/dpc-jax-cache.XXXXXX)  # the steps' compilation cache, empty at first
RUNS=$(mktemp -d /tmp/dpc-gpu-check-runs.XXXXXX)

if [ "${GPU_CHECK_INSTALL:-1}" = 1 ]; then  # the carried wheels (above), not flax
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl > "$OUT/install.log" 2>&1 || { echo "install failed"; exit 3; }
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
fi
$PY -c "import jax, jaxlib, mujoco, flax; print('jax', jax.__version__, 'jaxlib', jaxlib.__version__,
'mujoco', mujoco.__version__, 'flax', flax.__version__, 'devices', jax.devices())" \
  > "$OUT/versions.txt" 2>&1

if [ "$SIZE" = tiny ]; then  # a CPU test of the script itself: every step, a few envs and steps
  DEVICE=cpu
  BENCH="--batches 2 --calls 1"; SCAN="--batches 2 --calls 1 --chunk 2"
  ENGINE=native  # the CPU's own engine for the evaluations (the bench is MJX on any device)
  TRAIN="--samples 300 --set data_envs=4 data_burn_in=20 eval_episodes=2 eval_steps=10 adapter.epochs=2"
  EVAL="--episodes 2 --steps 10"
  SAC="--samples 300 --set data_envs=4 eval_episodes=2 eval_steps=10 adapter.epochs=2 \
sac.num_timesteps=64 sac.num_envs=4 sac.epoch_steps=32 sac.eval_envs=2 sac.batch_size=16 \
sac.grad_updates_per_step=1 sac.min_replay_size=16 sac.actor_warmup_steps=0"
  T=(400 400 400 300 300 200 200 300 300)
  MPC="--engine native --batches 2 --calls 1 --rounds 1"
else
  DEVICE=gpu
  ENGINE=mjx
  BENCH="--batches 4096 32768 --calls 20"; SCAN="--batches 16384 --calls 10 --chunk 20"
  TRAIN=""
  EVAL="--episodes 1024"
  SAC="--set sac.num_timesteps=262144"  # one epoch of the GPU preset: 1,024 envs x 256 steps
  T=(150 120 120 180 120 120 90 240 150)
  MPC="--engine mjx --batches 4096 --calls 3 --rounds 1"
fi

step() {  # step NAME TIMEOUT COMMAND...: its log in $OUT/NAME.log (rc last), wall in NAME.ms
  local name=$1 limit=$2; shift 2
  local left=$((BUDGET - ($(date +%s) - START)))
  if [ "$left" -lt 20 ]; then echo "skipped (budget spent)" > "$OUT/$name.log"; return; fi
  [ "$limit" -gt "$left" ] && limit=$left
  local t0; t0=$(date +%s%N)
  timeout "$limit" "$@" > "$OUT/$name.log" 2>&1
  echo "rc=$?" >> "$OUT/$name.log"
  echo $(( ($(date +%s%N) - t0) / 1000000 )) > "$OUT/$name.ms"  # wall, ms
}
DPC=(env "JAX_COMPILATION_CACHE_DIR=$CACHE" "$PY" -m dpc_mjx.run.cli)  # dpc-mjx, cached

step bench "${T[0]}" "${DPC[@]}" bench $BENCH
step bench_mpc "${T[8]}" env "JAX_COMPILATION_CACHE_DIR=$CACHE" "$PY" experiments/bench_mpc.py $MPC
rm -rf "$CACHE"/*  # the train starts cold
step train_cold "${T[3]}" "${DPC[@]}" train --device $DEVICE --run "$RUNS/cold" $TRAIN
step train_warm "${T[4]}" "${DPC[@]}" train --device $DEVICE --run "$RUNS/warm" $TRAIN
step eval_cold "${T[5]}" "${DPC[@]}" eval --device $DEVICE --engine $ENGINE $EVAL --out "$OUT/eval_cold.md"
step eval_warm "${T[6]}" "${DPC[@]}" eval --device $DEVICE --engine $ENGINE $EVAL --out "$OUT/eval_warm.md"
step sac "${T[7]}" "${DPC[@]}" train --device $DEVICE --recipe paper --run "$RUNS/sac" $SAC
# last, what the budget leaves: the per-call floor, and what XLA's command buffers do to it
step bench_scan "${T[1]}" "${DPC[@]}" bench $SCAN
XLA_FLAGS="--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUDNN,CUSTOM_CALL,CONDITIONAL,WHILE" \
  step bench_cmdbuf "${T[2]}" "${DPC[@]}" bench $SCAN
for run in cold warm sac; do
  cp "$RUNS/$run/summary.json" "$OUT/summary_$run.json" 2>/dev/null
done
$PY experiments/gpu_check_table.py "$OUT" | tee "$OUT/table.md"
rm -rf "$CACHE" "$RUNS"
