#!/bin/bash
# Runs a probe folder's run_one.sh on each line of its jobs file, P at a time (default 2; one core
# each), and appends each run's line to <folder>/queue.log.
# Usage: [P=2] run_jobs.sh FOLDER [JOBS_FILE]   (JOBS_FILE defaults to FOLDER/jobs.txt)
dir=$(cd "$1" && pwd)
jobs=${2:-$dir/jobs.txt}
xargs -P "${P:-2}" -L 1 "$dir/run_one.sh" < "$jobs" >> "$dir/queue.log" 2>&1
