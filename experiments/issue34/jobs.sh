# Sourced by this folder's study scripts (geometry.sh, learning_rate.sh), with R set to
# the study's run folder: moves to the repository root, one thread per process, and
# train CFG BACKEND SEEDS FIRST FOLDER queues `python train.py gpu` on the CPU, two
# processes at a time (one per core), skipping a run folder that has its agent (so a
# study resumes where it stopped) and starting an unfinished one over. The caller waits
# for the queue with `wait`.
set -u
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
C=experiments/issue34/cfg
mkdir -p "$R"
train() {  # cfg backend seeds first-seed folder
  [ -f "$R/$5/seed_$4/agent.json" ] && return
  rm -rf "${R:?}/$5"  # an unfinished run starts over (train.py gpu has no resume)
  while [ "$(jobs -rp | wc -l)" -ge 2 ]; do wait -n; done
  python train.py gpu --config $C/$1.yml --device cpu --backend $2 --seeds $3 --seed $4 \
      --out $R/$5 > $R/$5.log 2>&1 &
}
