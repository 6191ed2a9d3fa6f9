"""The score the tracking reports rank candidates by, from one reconstruction of a synthetic set (shared by the
report scripts: jaw21, unpaired21, curv22).

Score = accepted sightings within 3 px - 10 x accepted sightings over 3 px, over the sightings the truth calls
visible in both views (lipgen.evaluate.scoring.tracking_table)."""
from lipgen.evaluate.scoring import load_truth, tracking_table


def score_row(ds, rec, name, variant, cpu):
    """The JSON row of one set and variant: visible, accepted, share (%), within, over, score, cpu (s). The truth
    is read here, after the tracking."""
    t = tracking_table(load_truth(ds), rec)   # per view: accepted, rejected, lost, accepted over 3 px
    acc = sum(t[v]["accepted"] for v in t)
    over = sum(t[v]["wrong_over_3px"] for v in t)
    vis = sum(t[v]["accepted"] + t[v]["rejected"] + t[v]["lost"] for v in t)
    within = acc - over
    return dict(set=name, variant=variant, visible=vis, accepted=acc, share=round(100 * acc / vis, 2),
                within=within, over=over, score=within - 10 * over, cpu=round(cpu, 1))


def run_and_score(path, variant, settings, rec_path):
    """Reconstruct the set at ``path`` with ``settings`` on one BLAS thread, save it to ``rec_path`` and return
    its :func:`score_row` (cpu: this process's CPU seconds for the reconstruction, calibration included when it
    is the process's first of this set)."""
    import os
    import time

    from lipgen._threads import blas_threads
    from lipgen.dataset.layout import Dataset
    from lipgen.recon.pipeline import reconstruct_dataset

    t = time.process_time()
    with blas_threads(1):
        rec = reconstruct_dataset(path, settings=settings)
    cpu = time.process_time() - t
    rec.save(rec_path)
    return score_row(Dataset(path), rec, os.path.basename(str(path).rstrip("/")), variant, cpu)


def run_sets(argv, settings_for):
    """The loop of the run scripts (bh24, bh25, mc26): ``argv`` is ``[OUT.jsonl, "A,B", SET...]``; for each set, each
    variant in turn (one process, so one calibration per set) is run by :func:`run_and_score` with
    ``settings_for(variant)`` and its row appended to OUT.jsonl. Reconstructions go to ``$REC_DIR`` (default
    ``rec``) as ``SET.VARIANT.npz``."""
    import json
    import os

    rec_dir = os.environ.get("REC_DIR", "rec")
    os.makedirs(rec_dir, exist_ok=True)
    with open(argv[0], "a") as out:
        for path in argv[2:]:
            name = os.path.basename(path.rstrip("/"))
            for var in argv[1].split(","):
                row = run_and_score(path, var, settings_for(var), os.path.join(rec_dir, f"{name}.{var}.npz"))
                print(json.dumps(row), file=out, flush=True)
