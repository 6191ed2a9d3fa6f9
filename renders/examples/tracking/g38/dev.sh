#!/bin/bash
cd /work/wt/g38
export PYTHONPATH=/work/wt/g38 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
.venv/bin/python /work/b38/run.py /work/b38/dev_$1.jsonl main,GF,GFA "${@:2}" > /work/b38/dev_$1.log 2>&1
