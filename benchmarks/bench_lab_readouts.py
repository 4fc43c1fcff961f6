"""Every read-out of the baseline comparison on a lab's rod, beside the one-feature references.

    python benchmarks/bench_lab_readouts.py [--rate 2000] [--full] [--rod lab|other]
    ... [--seed 9] [--work DIR] [--set KEY=VALUE ...] [--json PATH]

The lab's rod of ``tests/lab_antenna.py`` (another antenna, written without the package's
physics: its first mode falls with distance, its materials differ only in decay time), four
materials at four distances, ten repetitions, recorded as ADC counts on a clock from 2.5 s,
imported with ``snn-antenna data import`` and read out by ``studies/baseline_comparison.toml``
(quick unless ``--full``). ``--rod other`` records another lab's rod instead
(``lab_antenna.OTHER_ROD``: five materials, another frequency law and mode ratio) and
``--seed`` another session: the rules fitted on the calibration contacts, read out of
sample. Each row: a read-out's mean score over the comparison's splits and the one-feature
read-out's on the same training and test contacts (material: accuracy against the decay
time's; distance: rmse in mm against the low peak frequency's), and whether it meets the mark
(within 5 points; within 2x). ``--work`` keeps the import and the run to re-read; the import
is made again when the rod, the seed or the importer's code changes (``import_key``).
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))        # the lab's rod lives with the tests

import lab_antenna as lab  # noqa: E402

from snn_antenna.cli import main as cli  # noqa: E402
from snn_antenna.report.results import write_benchmark_json  # noqa: E402
from snn_antenna.sources import recorded  # noqa: E402

ORIGIN_S = 2.5


# what the written and imported session depends on: the lab's rod, the files it is written
# to, and the importer that reads them (the package's data layer and its recorded sources)
IMPORT_CODE = (ROOT / "tests" / "lab_antenna.py", Path(__file__).resolve(),
               *sorted((ROOT / "snn_antenna" / "data").glob("*.py")),
               ROOT / "snn_antenna" / "sources" / "recorded.py")


#: the rods a session is recorded on (``lab_antenna.session``'s keys)
RODS = {"lab": {}, "other": lab.OTHER_ROD}


def import_key(rate_hz: float, rod: str = "lab", seed: int = 9) -> str:
    """The import's cache key: the rate, rod and seed and the bytes of every file of
    ``IMPORT_CODE``."""
    digest = hashlib.sha256(f"{rate_hz!r} {rod} {seed}".encode())
    for path in IMPORT_CODE:
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:16]


def imported(work: Path, rate_hz: float, rod: str = "lab", seed: int = 9
             ) -> tuple[Path, object]:
    """(the imported folder, its source): the session of ``rod`` (``RODS``) and ``seed``
    written and imported once per ``work`` folder and ``import_key`` (a changed rod or
    importer imports again)."""
    folder = work / f"import-{import_key(rate_hz, rod, seed)}"
    ds = folder / "ds"
    if not ds.exists():
        materials = tuple(RODS[rod].get("decay_s", lab.DECAY_S))
        sess = lab.session(rate_hz, materials=materials, repetitions=10, seed=seed,
                           **RODS[rod])
        (folder / "recs").mkdir(parents=True, exist_ok=True)
        lab.counts_csv(folder / "recs" / "r1.csv", lab.adc_counts(sess.g[:, :2], 10, 18.0),
                       rate_hz, origin_s=ORIGIN_S)
        labels = lab.labels_csv(folder / "labels.csv", sess, "r1", origin_s=ORIGIN_S)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli(["data", "import", str(folder / "recs"), str(labels), "--out",
                        str(ds)])
        if code:
            sys.exit(err.getvalue())
    return ds, recorded.open_bench(ds)


#: the mark a read-out meets, as the JSON states it
MARK = ("meets: a material accuracy at least the one-feature read-out's minus 0.05, a "
        "distance rmse at most twice the one-feature read-out's (the mean over the splits)")


def meets(mine: float, reference: float, task: str) -> bool:
    """The mark (:data:`MARK`): material accuracy within 5 points of the one-feature
    read-out's; distance rmse within 2x of it."""
    return mine >= reference - 0.05 if task == "material" else mine <= 2 * reference


def table(scores: dict) -> list[str]:
    rows = [f"{'read-out':34s} {'task':8s} {'score':>8s} {'one-feature':>11s}  mark"]
    for name, (mine, reference, task) in sorted(scores.items(), key=lambda kv: (kv[1][2],
                                                                                 kv[0])):
        mark = "meets" if meets(mine, reference, task) else "MISSES"
        if task == "material":
            rows.append(f"{name:34s} {task:8s} {mine:8.3f} {reference:11.3f}  {mark}")
        else:
            rows.append(f"{name:34s} {task:8s} {mine:6.1f}mm {reference:9.1f}mm  {mark}")
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rate", type=float, default=2000.0)
    p.add_argument("--full", action="store_true", help="the full profile (default: quick)")
    p.add_argument("--rod", choices=sorted(RODS), default="lab",
                   help="the lab's rod, or another lab's (lab_antenna.OTHER_ROD)")
    p.add_argument("--seed", type=int, default=9, help="the recorded session's seed")
    p.add_argument("--work", type=Path, default=None, help="folder for the import and run")
    p.add_argument("--set", action="append", default=[], dest="sets")
    p.add_argument("--json", metavar="PATH", help="write the rows as JSON here")
    args = p.parse_args(argv)
    work = args.work or Path(f"/tmp/lab_readouts_{int(args.rate)}")
    ds, source = imported(work, args.rate, args.rod, args.seed)
    run = work / ("run_full" if args.full else "run_quick")
    sets = [f"stimulus.cache_dir=\"{work / 'cache'}\"", "spiking.workers=1", *args.sets]
    command = ["run", str(ROOT / "studies" / "baseline_comparison.toml"), "--data",
               str(ds), *([] if args.full else ["--quick"]), "--out", str(run),
               "--yes", "--force"]
    for s in sets:
        command += ["--set", s]
    started = time.perf_counter()
    code = cli(command)
    if code:
        return code
    wall = time.perf_counter() - started
    print(f"# {args.rod} rod, seed {args.seed}, {args.rate:g} Hz, "
          f"{'full' if args.full else 'quick'}, {wall:.0f} s")
    scores = lab.against_one_feature(run, source)
    print("\n".join(table(scores)))
    if args.json:   # per task, each read-out's row under its key (the page names it)
        tasks = {"material": "material_accuracy", "distance": "distance_rmse_mm"}
        values = {"rate_hz": args.rate, "rod": args.rod, "seed": args.seed,
                  "profile": "full" if args.full else "quick",
                  "settings": args.sets, "wall_s": wall, "marked": MARK,
                  **{key: {} for key in tasks.values()}}
        for name, (mine, reference, task) in sorted(scores.items()):
            values[tasks[task]][name] = {
                "score": mine, "one_feature": reference,
                "mark": "meets" if meets(mine, reference, task) else "misses"}
        write_benchmark_json(args.json, values)
    return 0


if __name__ == "__main__":
    sys.exit(main())
