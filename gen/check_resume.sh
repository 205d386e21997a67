#!/bin/sh
# Cut a training run off after its first checkpoint, resume it, and compare with an
# uninterrupted run: the weights and the recorded loss must be identical (about 2 minutes).
#   sh gen/check_resume.sh [MODEL]      (default snow_2d, 400 iterations)
set -eu
cd "$(dirname "$0")/.."
model=${1:-snow_2d}
PY=${PY:-/usr/bin/python3}
rm -f gen/ckpt/resume_a.* gen/ckpt/resume_b.*
$PY gen/train.py --model "$model" --iters 400 --tag resume_a --quiet
PN_CKPT_SECONDS=2 $PY gen/train.py --model "$model" --iters 400 --tag resume_b --quiet &
pid=$!
while [ ! -f gen/ckpt/resume_b.pt ]; do sleep 1; done
sleep 3
kill "$pid"
wait "$pid" 2>/dev/null || true
$PY gen/train.py --model "$model" --iters 400 --tag resume_b --quiet
$PY - <<'PYEOF'
import sys, torch
a = torch.load("gen/ckpt/resume_a.done.pt"); b = torch.load("gen/ckpt/resume_b.done.pt")
same = all(torch.equal(a["model"][k], b["model"][k]) for k in a["model"]) and a["final_loss"] == b["final_loss"]
print("resumed run identical to the uninterrupted one:", same)
sys.exit(0 if same else 1)
PYEOF
rm -f gen/ckpt/resume_a.* gen/ckpt/resume_b.*
