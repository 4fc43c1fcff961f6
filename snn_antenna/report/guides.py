"""What the guides show of each study's stored run: its figures, its run time, its size.

``snn-antenna results`` (:mod:`snn_antenna.report.results`) stores each study's summary
beside the results page (``docs/results/STUDY.json``); from a run's output folder it also
copies the figures a guide shows (:data:`GUIDE_FIGURES`) into ``figures/`` there, a folder
per study.
From those stored files alone it writes, for each study, the text a guide includes
(``guide_`` and the study's name, beside the summaries: the run time, n and each figure
with its caption) and the
table of run times the home page includes (``docs/results/run_times.md``). A guide cites no
number of its own: it includes its fragment, so its run time and figures are the stored run's
and change only with the results command::

    ```{include} ../results/guide_gating_threshold.md
    ```

Each fragment is a pure function of the stored summary and the figure files beside it
(:func:`guide_fragment`), so the results command gives the same fragments from the same
sources, and a test regenerates them to show it.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..core.files import atomic_write

#: where a study's summary keeps its own measured wall time, first found first
RUN_TIME = ("/total_wall_s", "/total_s", "/timing/total_s")

#: what a study's run is made of, per study: (pointer, what one unit is); a list counts its
#: entries
SIZES: dict[str, tuple[tuple[str, str], ...]] = {
    "quickstart": (("/score/contacts", "contacts scored"),),
    "tuning_sweep": (("/points", "grid points"),),
    "gating_threshold": (("/seeds/used", "seeds"),),
    "baseline_comparison": (("/data/n_events", "bench contacts"),),
    "model_selection": (("/data/seeds", "seeds"),
                        ("/data/events_per_point", "contacts per point")),
    "speed_accuracy": (("/rows", "runs in the main sweep"),),
    "exploration": (("/contacts", "contacts met"),),
    "bank_tuning": (("/seeds", "seeds"), ("/trials", "trials"), ("/events", "bench contacts")),
}

#: the figures each study's guide shows, by the report's file name (without ``.png``), and
#: what a reader takes from each: how to read it, never what it shows (that is the run's)
GUIDE_FIGURES: dict[str, dict[str, str]] = {
    "quickstart": {
        "rate_map": "Read the contact where the activity leaves the self-motion neurons "
        "for the higher ones; the distance decoded from them is in the run's table.",
    },
    "tuning_sweep": {
        "tuning_curves": "A narrow curve whose peak sits where the k axis predicts is a "
        "neuron that resolves frequency; a flat or shifted one is not.",
        "heatmaps": "Where the rate changes across b and I tells which settings the tuning "
        "depends on; a uniform region is a setting that does not matter there.",
    },
    "gating_threshold": {
        "f1_vs_threshold": "Each curve's peak is the best fixed threshold for one speed: "
        "peaks at different thresholds are what a gate that follows speed is for.",
        "f1_methods": "Compare each method's interval with the others': where intervals "
        "overlap the seeds do not tell the methods apart.",
        "gate": "Read the gate's chosen threshold against the speed it sees: it should follow "
        "the speeds it was trained on and stay near them at a held-out speed.",
    },
    "baseline_comparison": {
        "pareto_cost_accuracy": "Up is more accurate, left is cheaper; a pipeline off the "
        "line is beaten on both by one on it.",
        "fig6d_confusion": "The diagonal is the share read correctly; the off-diagonal cells "
        "name which materials are taken for which.",
        "tuned_curve": "How the tuned bank's accuracy grows with its size, beside the FFT "
        "read-out on the same splits: where the curves meet, more resonators buy nothing.",
        "chosen_bank_on_spectra": "Each row below is one of the chosen bank's bands: its bar "
        "should cover a line where the materials' spectra above differ, its ticks (the "
        "resonators) sit inside it.",
    },
    "model_selection": {
        "model_selection": "A candidate whose predictions sit on the paper's values and "
        "inside the acceptance bounds is kept; the bars show how far seeds move it.",
    },
    "speed_accuracy": {
        "pareto": "Down is more accurate, left is cheaper; the settings on the black line are "
        "the ones worth choosing, the others are beaten on both.",
        "stability_map": "The boundary between accurate and inaccurate cells is the largest "
        "k·dt a method can be given; beyond the non-finite boundary it blows up.",
    },
    "exploration": {
        "exploration": "Follow the rate map to the first contact: the detection line should "
        "sit just after the true contact and the stop just after the detection.",
    },
    "bank_tuning": {
        "pareto_front": "Up is more accurate, left is cheaper; the coloured front is what the "
        "tuning offers, the ringed point where it started.",
        "resonators_on_spectra": "Each row below is one of the chosen bank's bands: its bar "
        "should cover a line where the materials' spectra above differ; a resonator outside "
        "every bar reads nothing that tells them apart.",
    },
}

#: where the fragments' figures are, from the documentation's root (Sphinx reads a path that
#: starts with ``/`` from there, whichever page includes the fragment)
FIGURES = "figures"


def _resolve(document: Any, ptr: str) -> Any:
    value = document
    for token in ptr.split("/")[1:]:
        value = value[int(token)] if isinstance(value, list) else value[token]
    return value


def run_time(summary: dict) -> tuple[str, float] | None:
    """The stored run's own wall time in seconds and where its summary keeps it."""
    for ptr in RUN_TIME:
        try:
            value = _resolve(summary, ptr)
        except (KeyError, IndexError, TypeError, ValueError):
            continue
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return ptr, float(value)
    return None


def duration(seconds: float) -> str:
    """A run time in words: seconds below two minutes, minutes below two hours, else hours."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def sizes(study: str, summary: dict) -> list[str]:
    """What the run was made of, in words (``5 seeds``, ``12799 bench contacts``)."""
    found = []
    for ptr, what in SIZES.get(study, ()):
        try:
            value = _resolve(summary, ptr)
        except (KeyError, IndexError, TypeError, ValueError):
            continue
        if isinstance(value, list):
            value = len(value)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            found.append(f"{value:g} {what}")
    return found


def _made_on(summary: dict) -> str:
    prov = summary.get("provenance", {})
    machine = prov.get("machine") or prov.get("platform", "an unnamed machine")
    commit = prov.get("git_commit") or "no commit"
    return (f"on {machine}, {str(prov.get('created', '?'))[:10]}, commit `{commit}`, code hash "
            f"`{prov.get('code_sha256', '?')}`")


def _alt(study: str, name: str, caption: str) -> str:
    """A figure's short text for a reader who cannot see it: the study, the file and the
    caption's first sentence."""
    first = caption.split(". ")[0].rstrip(".")
    if len(first) > 120:
        first = first[:117].rsplit(" ", 1)[0] + " …"
    return f"{study.replace('_', ' ')}, {name}: {first}"


def guide_fragment(study: str, summary: dict, figures: list[str]) -> str:
    """The text a study's guide includes: the stored run's profile, run time and size, and
    each figure of ``figures`` (file names present in ``figures/STUDY/``) with its caption."""
    timed = run_time(summary)
    size = sizes(study, summary)
    quick = bool(summary.get("quick"))
    lines = [f"% written by `snn-antenna results` from results/{study}.json; never edited", ""]
    took = f"ran in {duration(timed[1])}" if timed else "ran (its summary records no run time)"
    if quick:
        lines.append(
            f"**Run time.** Only a quick check of this study is stored: its quick profile "
            f"(`--quick`) {took} {_made_on(summary)}. The full profile's run time appears here "
            f"when its run is on the results page."
        )
    else:
        lines.append(
            f"**Run time.** The full profile (`snn-antenna run studies/{study}.toml`) {took} "
            f"{_made_on(summary)}"
            + (f", for {', '.join(size)}" if size else "")
            + "."
        )
    lines += ["", f"Its numbers: {{ref}}`the results page <run-{study}>`.", ""]
    captions = summary.get("figure_captions") or {}
    for name in figures:
        stem = name.removesuffix(".png")
        what = captions.get(name) or f"The run's `{name}`."
        n = f" n: {', '.join(size)}." if size else ""
        profile = " Quick profile: a check, not a result." if quick else ""
        read = GUIDE_FIGURES.get(study, {}).get(stem, "")
        lines += [
            "```{figure} " + f"/results/{FIGURES}/{study}/{name}",
            f":alt: {_alt(study, name, what)}",
            ":width: 100%",
            "",
            f"{what}{n}{profile} {read}".strip(),
            "```",
            "",
        ]
    return "\n".join(lines).rstrip("\n") + "\n"


def run_times_table(stored: list[tuple[str, dict]]) -> str:
    """The home page's table: each study, its guide, its stored run's profile and run time."""
    lines = [
        "% written by `snn-antenna results` from the results page's sources; never edited",
        "",
        "| study | guide | stored run | run time |",
        "| --- | --- | --- | --- |",
    ]
    for study, summary in stored:
        timed = run_time(summary)
        profile = "quick check" if summary.get("quick") else "full profile"
        lines.append(
            f"| `{study}` | {{doc}}`/guide/{study}` | {profile} | "
            f"{duration(timed[1]) if timed else '–'} |"
        )
    return "\n".join(lines) + "\n"


def shown_figures(study: str, summary: dict) -> list[str]:
    """The figure files of ``study``'s run a guide shows, in the report's order."""
    wanted = GUIDE_FIGURES.get(study, {})
    return [name for name in summary.get("figures") or [] if name.removesuffix(".png") in wanted]


def _regular(path: Path) -> bool:
    return path.is_file() and not path.is_symlink()


def run_figures(study: str, summary: dict, run_dir: Path) -> list[str]:
    """The guide figures of ``study`` its run's folder holds."""
    return [name for name in shown_figures(study, summary) if _regular(run_dir / name)]


def stored_figures(study: str, summary: dict, store: Path) -> list[str]:
    """The guide figures of ``study`` that are stored beside the page."""
    folder = store / FIGURES / study
    return [name for name in shown_figures(study, summary) if _regular(folder / name)]


def copy_figures(study: str, names: list[str], run_dir: Path, store: Path) -> None:
    """Copy the run's guide figures ``names`` into ``store/figures/STUDY/``; a guide figure of
    an earlier stored run that this run did not draw is removed (only a regular file named as
    one of the study's ``GUIDE_FIGURES``, which only this command writes there: nothing else
    is followed or touched)."""
    target = store / FIGURES / study
    target.mkdir(parents=True, exist_ok=True)
    for name in names:
        atomic_write(target / name, (run_dir / name).read_bytes())
    for entry in os.scandir(target):
        if entry.name.endswith(".png") and entry.name not in names \
                and entry.name.removesuffix(".png") in GUIDE_FIGURES.get(study, {}) \
                and entry.is_file(follow_symlinks=False):
            os.unlink(entry.path)


def fragments(store: Path, stored: list[tuple[str, dict, list[str]]]) -> dict[Path, str]:
    """Each study's guide fragment (from its summary and its figures' names) and the table of
    run times, by the file each is written to."""
    made = {store / f"guide_{study}.md": guide_fragment(study, summary, figures)
            for study, summary, figures in stored}
    made[store / "run_times.md"] = run_times_table([(study, summary)
                                                     for study, summary, _ in stored])
    return made
