#!/usr/bin/python3
"""Regenerate the shipped models: train (resuming any checkpoint), export, measure, re-export.

    /usr/bin/python3 gen/make_models.py [NAME ...] [--jobs 2]     (make models [MODEL=NAME])

1. Train every named model (all by default) with gen/train.py, up to --jobs at a time, each on
   one thread: learned return mappings first, since energies that use them train against them.
   A model whose gen/ckpt/NAME.done.pt exists is not retrained; delete it to retrain.
2. Export each to models/pn_model_NAME.h, build bench/model_report.c against it, and export
   again with the quality lines model_report measured in the banner.
Reduced-order models rom_SCENE (rom_cylinder, rom_cuboid, rom_poke, rom_tower) train with
gen/rom_train.py on the snapshots of make rom-data (data/rom/SCENE), resuming
gen/ckpt/rom_SCENE.pt, and export with gen/rom_export.py to models/rom_SCENE.h.
Training is deterministic (seeded per iteration, one thread), so the headers are reproducible.
"""
import argparse
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
from models import MODELS  # noqa: E402

PY = sys.executable or "/usr/bin/python3"
ROM_MODELS = ["rom_cylinder", "rom_cuboid", "rom_poke", "rom_tower"]


def train_command(n):
    """The training command of model n: gen/rom_train.py for rom_SCENE, else gen/train.py."""
    if n in ROM_MODELS:
        return [PY, os.path.join(HERE, "rom_train.py"), n[4:], "--threads", "1", "--quiet"]
    return [PY, os.path.join(HERE, "train.py"), "--model", n, "--quiet"]


def run_parallel(names, jobs, done=None):
    """Train names, at most jobs at once, calling done(name) after each; stop on the first failure."""
    queue, running = list(names), []
    while queue or running:
        while queue and len(running) < jobs:
            n = queue.pop(0)
            log = open(os.path.join(ROOT, "build", "train_%s.log" % n), "a")
            print("training %s (log build/train_%s.log)" % (n, n), flush=True)
            running.append((n, subprocess.Popen(train_command(n), stdout=log, stderr=subprocess.STDOUT)))
        time.sleep(1)
        for item in list(running):
            n, p = item
            if p.poll() is not None:
                running.remove(item)
                if p.returncode != 0:
                    for _, q in running:
                        q.terminate()
                    sys.exit("training %s failed: see build/train_%s.log" % (n, n))
                print("trained %s" % n, flush=True)
                if done:
                    done(n)


def export_rom(n):
    subprocess.check_call([PY, os.path.join(HERE, "rom_export.py"), n[4:]])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="*", help="models to make (default: all)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--times", action="store_true", help="print each trained model's training time")
    a = ap.parse_args()
    if a.times:
        import torch
        for n in a.names or list(MODELS):
            p = os.path.join(HERE, "ckpt", n + ".done.pt")
            if os.path.exists(p):
                st = torch.load(p)
                print("%-22s %6.0f s  %6d iterations  final loss %.4g" % (n, st["seconds"], MODELS[n]["iters"], st["final_loss"]))
        return
    names = a.names or [n for n in MODELS if MODELS[n]["ship"]] + ROM_MODELS
    for n in names:
        if n not in MODELS and n not in ROM_MODELS:
            sys.exit("unknown model %s; known: %s" % (n, " ".join(list(MODELS) + ROM_MODELS)))
    os.makedirs(os.path.join(ROOT, "build"), exist_ok=True)
    run_parallel([n for n in names if n in ROM_MODELS], a.jobs, export_rom)
    names = [n for n in names if n not in ROM_MODELS]
    if not names:
        return
    # a model's learned return mapping comes first, even if only the energy was named
    need = []
    for n in names:
        rm = MODELS[n].get("return_map")
        if rm and rm not in need:
            need.append(rm)
    for n in names:
        if n not in need:
            need.append(n)
    os.makedirs(os.path.join(ROOT, "build"), exist_ok=True)
    first = [n for n in need if MODELS[n]["kind"] == "return_map"]
    run_parallel(first, a.jobs)
    run_parallel([n for n in need if n not in first], a.jobs)
    cc = os.environ.get("CC", "cc")
    report = os.path.join(ROOT, "build", "model_report")
    for n in need:
        subprocess.check_call([PY, os.path.join(HERE, "export.py"), "--model", n], stdout=subprocess.DEVNULL)
    subprocess.check_call([cc, "-std=c99", "-O2", os.path.join(ROOT, "bench", "model_report.c"), "-lm",
                           "-o", report])
    for n in need:
        q = os.path.join(ROOT, "build", "quality_%s.txt" % n)
        with open(q, "w") as f:
            subprocess.check_call([report, "--model", n, "--banner"], stdout=f)
        print(subprocess.check_output([PY, os.path.join(HERE, "export.py"), "--model", n, "--quality", q]).decode(),
              end="", flush=True)


if __name__ == "__main__":
    main()
