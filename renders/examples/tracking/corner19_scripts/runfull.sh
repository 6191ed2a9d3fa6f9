#!/bin/bash
cd /work/corner19
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
while kill -0 $(cat runmain2.pid) 2>/dev/null; do sleep 5; done
H17_SETTINGS='{"lost_neighbour_ratio": 0.5}' PYTHONPATH=/work/corner19/cand nice -n 10 /work/main/.venv/bin/python trackscore.py K1full hard_s62 >> full.txt 2>>log_full.err
H17_SETTINGS='{"lost_neighbour_ratio": 0.5, "lost_neighbour_neither": 0.5}' PYTHONPATH=/work/corner19/cand nice -n 10 /work/main/.venv/bin/python trackscore.py K2full hard_s55 >> full.txt 2>>log_full.err
echo "$(date -u +%H:%M:%S) full done" >> full.txt
