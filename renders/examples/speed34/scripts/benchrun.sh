#!/bin/bash
# lipgen bench --suite generate for each NAME=TREE argument, one after another
cd /tmp
for arg in "$@"; do
  name=${arg%%=*}; tree=${arg#*=}
  PYTHONPATH=$tree /work/main/.venv/bin/python -m lipgen bench --suite generate --out /work/b34/bench_gen_${name}.json --force > /work/b34/bench_${name}.log 2>&1
done
echo finished >> /work/b34/benchrun.done
