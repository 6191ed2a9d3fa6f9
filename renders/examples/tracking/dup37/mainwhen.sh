#!/bin/bash
# run main (fd4b916 worktree) on each B set with a span, once; until all listed sets have a B row
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
done_sets=""
while true; do
  for s in $(/work/main/.venv/bin/python -c "
import json
for l in open('/work/b37/hoB.jsonl'):
    r=json.loads(l)
    if r['variant']=='B' and r.get('shared'): print(r['set'])"); do
    case " $done_sets " in *" $s "*) continue;; esac
    done_sets="$done_sets $s"
    cd /tmp && PYTHONPATH=/work/wt/m37 /work/main/.venv/bin/python /work/b37/run.py /work/b37/hoB.jsonl main $s
  done
  n=$(grep -c '"variant": "B"' /work/b37/hoB.jsonl)
  [ "$n" -ge 19 ] && [ -z "$(comm -23 <(/work/main/.venv/bin/python -c "
import json
for l in open('/work/b37/hoB.jsonl'):
    r=json.loads(l)
    if r['variant']=='B' and r.get('shared'): print(r['set'])" | sort) <(echo $done_sets | tr ' ' '\n' | sort))" ] && break
  sleep 20
done
echo finished
