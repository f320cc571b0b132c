#!/bin/bash
# Run the issue-12 ablation queue: one training process at a time, in priority order.
# Each line of queue.txt is "VARIANT SEED"; the file is re-read before each run so the
# order can change while the queue runs. Stops before a run that cannot end by DEADLINE.
cd "$(dirname "$0")/../.." || exit 1
. .venv/bin/activate
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
STEPS=${STEPS:-1000000}
DEADLINE=$(date -u -d "${DEADLINE_AT:-today 17:29:00}" +%s)
EST=${EST:-660}   # expected seconds per run (train + eval), updated from the last run
OUT=experiments/issue12/runs
mkdir -p $OUT
while true; do
  next=""
  while read -r variant seed; do
    [ -z "$variant" ] && continue
    case "$variant" in \#*) continue;; esac
    d=$OUT/${variant}_s${seed}
    if [ ! -f "$d/result.json" ] && [ ! -f "$d/started" ]; then next="$variant $seed"; break; fi
  done < experiments/issue12/queue.txt
  [ -z "$next" ] && { echo "$(date -u +%T) queue empty"; break; }
  set -- $next
  now=$(date -u +%s); left=$((DEADLINE - now))
  if [ $left -lt $EST ]; then echo "$(date -u +%T) stop: $left s left < $EST s per run"; break; fi
  d=$OUT/${1}_s${2}; mkdir -p $d; date -u +%FT%TZ > $d/started
  echo "$(date -u +%T) start $1 $2 (est $EST s, $left s left)"
  t0=$(date +%s)
  timeout $left nice -n 10 python experiments/issue12/run.py "$1" "$2" --steps $STEPS --out $OUT > $d/log.txt 2>&1
  rc=$?; t1=$(date +%s)
  echo "$(date -u +%T) end $1 $2 rc=$rc wall=$((t1 - t0)) s"
  echo "{\"rc\": $rc, \"wall_total_s\": $((t1 - t0))}" > $d/process.json
  [ $rc -eq 0 ] && EST=$(( (t1 - t0) * 11 / 10 ))
done
