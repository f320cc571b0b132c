#!/bin/bash
# Runs jobs.txt two at a time (one core each), logs to queue.log.
cd "$(dirname "$0")"
xargs -P 2 -L 1 ./run_one.sh < jobs.txt >> queue.log 2>&1
