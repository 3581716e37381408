"""Model cards: what a shipped model was trained on, how, and how well it does on the test split."""

from __future__ import annotations

from pathlib import Path

from ..core.sensors import load_sensor_config


def beside(report_path: Path, suffix: str) -> Path:
    """A file kept with a training report: <model>.train.json -> <model><suffix> (the
    ablation's .augment.json, the .checkpoint.npz)."""
    return Path(report_path).with_name(Path(report_path).name.removesuffix(".train.json") + suffix)


def augmentation_table(report_path: Path, columns: dict[str, str]) -> str:
    """The augmentation ablation (<model>.augment.json, `sparse-body train ... --ablate-augment`)
    as a Markdown table of validation figures, or a line saying it has not been run."""
    import json

    path = beside(report_path, ".augment.json")
    if not path.is_file():
        return f"(no ablation: `{path.name}` is missing; `sparse-body train ... --ablate-augment` writes it)"
    report = json.loads(path.read_text())
    rows = [
        "| augmentation | steps | minutes | " + " | ".join(columns.values()) + " |",
        "|---|---:|---:|" + "---:|" * len(columns),
    ]
    for run in report["runs"]:
        rows.append(
            f"| {run['augment']} | {run['steps']} | {run['minutes']:.1f} | "
            + " | ".join(f"{run['validation'][key]:.4g}" if key in run["validation"] else "-" for key in columns)
            + " |"
        )
    return (
        f"Each row trained anew with the same seed and budget (`{report['command']}`); "
        "validation split (people the model never saw):\n\n" + "\n".join(rows)
    )


def _interval(run: dict, metric: str, by_person: bool = False) -> list[float] | None:
    """A results file's 95 % bootstrap interval of metric from the per-clip figures it keeps:
    clips drawn, or people drawn with all their clips (a person's clips move together)."""
    from ..core.results import clip_interval

    rows = [c for c in run["clips"] if metric in c and (c.get("subject") or not by_person)]
    units = [c["subject"] for c in rows] if by_person else None
    return clip_interval([{metric: c[metric]} for c in rows], [int(c["frames"]) for c in rows], units=units).get(metric)


def with_interval(run: dict, metric: str) -> str:
    """A results file's mean of metric with its 95 % interval, clips drawn ("7.83 [7.12, 8.55]")."""
    if metric not in run["summary"]:
        return "-"
    interval = _interval(run, metric)
    return f"{run['summary'][metric]:.2f}" + (f" [{interval[0]:.2f}, {interval[1]:.2f}]" if interval else "")


INTERVAL_NOTE = "(each mean with its 95 % interval, clips drawn with replacement)"


def runtime_choices_table(results_path: Path, command: str, metrics: tuple[str, ...]) -> str:
    """The runtime options compared in one `sparse-body eval --output` file (written by
    `command`), as a Markdown table (estimator specs as rows), or a line saying how to
    measure them."""
    import json

    path = Path(results_path)
    if not path.is_file():
        return f"(not measured: `{path.name}` is missing; `{command}` writes it)"
    results = json.loads(path.read_text())
    rows = ["| estimator | clips | " + " | ".join(metrics) + " |", "|---|---:|" + "---:|" * len(metrics)]
    for r in results:
        rows.append(
            f"| `{r['estimator']}` | {len(r['clips'])} | " + " | ".join(with_interval(r, m) for m in metrics) + " |"
        )
    return (
        f"`{command}` ({results[0]['split']} split, {results[0]['protocol']}):\n\n"
        + "\n".join(rows)
        + f"\n\n{INTERVAL_NOTE}"
    )


# How a card names the field protocol of its test-split tables (data/field_protocol.py, "field")
FIELD_PROTOCOL = (
    "Field protocol (the default, `--protocol field`: the body from a T-pose calibration; trackers worn as a "
    "user wears them, turned up to 20 degrees and 1.5 cm per axis off, where they sit found by the mounting "
    "calibration from movement; a VR system's noise; each hand controller lost 3 % of the time, a Lighthouse "
    "jump a minute, IMU heading drift up to 2 degrees a minute; docs/methods.md)"
)
# the noise tables' protocol: the field without failures, so that the noise alone shows
NOISE_HEADING = "## Tracker noise (field-exact protocol, `--noise none` against `--noise lobstr`)"

# what a lost hand costs, where the protocol loses hands (the field's): "-" in a table without
LOSS_COLUMNS = ("Lost PE [cm]", "Recovery jump [cm]")
COLUMNS = (
    "MPJPE [cm]",
    "MPJRE [deg]",
    "MPJVE [cm/s]",
    "Jitter [100m/s3]",
    "Lower PE [cm]",
    "Toe PE [cm]",
    "End-effector PE [cm]",
    *LOSS_COLUMNS,
)


def measured_results(onnx_path: Path, evaluate_model, mocap_root: Path, limit: int | None, evaluate: bool) -> dict:
    """A card's measured JSON (<model>.eval.json): evaluate_model(onnx_path, mocap_root, limit)
    writes it, unless evaluate=False and it is there already (rewriting the text only)."""
    import json

    path = Path(onnx_path).with_suffix(".eval.json")
    if evaluate or not path.is_file():
        evaluate_model(onnx_path, mocap_root, limit)
    return json.loads(path.read_text())


def results_table(results: list[dict], columns=COLUMNS) -> str:
    """`sparse-body eval` JSON results as a Markdown table, one estimator a row."""
    rows = ["| estimator | " + " | ".join(columns) + " |", "|---|" + "---:|" * len(columns)]
    for r in results:
        rows.append(f"| `{r['estimator']}` | " + " | ".join(with_interval(r, c) for c in columns) + " |")
    first, metric = results[0], columns[0]
    people = [(r["estimator"], _interval(r, metric, by_person=True)) for r in results]
    shown = [f"`{name}` [{low_high[0]:.2f}, {low_high[1]:.2f}]" for name, low_high in people if low_high]
    count = len({c["subject"] for c in first["clips"] if c.get("subject")})
    by_person = f"; {metric} with people drawn ({count} people): " + ", ".join(shown) if shown else ""
    return (
        "\n".join(rows)
        + f"\n\n({len(first['clips'])} clips, {first['frames']} frames; {first['protocol']} protocol; {INTERVAL_NOTE[1:-1]}"
        + f"{by_person})"
    )


def _evaluate(job):
    from ..evaluation import evaluate

    _, spec, sensors_name, protocol, mocap_root, limit, options = job
    return evaluate(
        spec,
        load_sensor_config(sensors_name),
        mocap_root,
        "test",
        protocol=protocol,
        limit=limit,
        progress=False,
        **options,
    )


def evaluate_jobs(jobs: list[tuple], workers: int = 2) -> list:
    """A card's test-split evaluations, `workers` processes at a time, in order. A job is
    (tag, estimator spec, sensor configuration name, protocol, mocap root, limit, options)."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_evaluate, jobs))


NOISE_METRICS = ("MPJPE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]", "End-effector PE [cm]")
# a noise table's three runs of each estimator: clean trackers, LoBSTr's noise through the live
# filter, and the same smoothed offline (setup name, --noise, extra estimator options)
NOISE_SETUPS: tuple[tuple[str, str, dict[str, object]], ...] = (
    ("clean", "none", {}),
    ("noisy", "lobstr", {}),
    ("smoothed", "lobstr", {"smooth": True}),
)


def noise_jobs(runs: list[tuple[str, dict]], sensors_name: str, mocap_root: Path, limit: int | None) -> list[tuple]:
    """evaluate_jobs() jobs of a noise table: each (estimator spec, options) under each of
    NOISE_SETUPS, tagged with the setup's name."""
    from ..data.field_protocol import Protocol

    return [
        (setup, spec, sensors_name, Protocol.named(noise=noise), mocap_root, limit, {**options, **extra})
        for spec, options in runs
        for setup, noise, extra in NOISE_SETUPS
    ]


def noise_table(measured: dict[str, list[dict]]) -> str:
    """A Markdown table from noise_jobs()' results ({setup: [eval JSON of each estimator]}):
    each estimator clean, with LoBSTr's noise live and smoothed, and the ratios the noise brings."""
    rows = ["| estimator | trackers | " + " | ".join(NOISE_METRICS) + " |", "|---|---|" + "---|" * len(NOISE_METRICS)]
    for k, run in enumerate(measured["clean"]):
        clean = run["summary"]
        rows.append(
            f"| {run['estimator']}/{run['sensors']} | clean | "
            + " | ".join(with_interval(run, m) for m in NOISE_METRICS)
            + " |"
        )
        for label, setup in (("LoBSTr noise, live filter", "noisy"), ("LoBSTr noise, smoothed offline", "smoothed")):
            noisy = measured[setup][k]
            rows.append(f"| | {label} | " + " | ".join(with_interval(noisy, m) for m in NOISE_METRICS) + " |")
            rows.append(
                "| | ratio | " + " | ".join(f"{noisy['summary'][m] / clean[m]:.2f}x" for m in NOISE_METRICS) + " |"
            )
    return "\n".join(rows) + f"\n\n{INTERVAL_NOTE}"


def by_setup(jobs: list[tuple], results: list) -> dict[str, list[dict]]:
    """evaluate_jobs()' results as {setup tag: [eval JSON, in job order]}: a card's measured JSON."""
    measured: dict[str, list[dict]] = {}
    for job, result in zip(jobs, results, strict=True):
        measured.setdefault(job[0], []).append(result.to_json())
    return measured


def measure_card(path: Path, jobs: list[tuple], noise: dict[str, list[tuple]], workers: int = 2) -> Path:
    """Evaluate a card's jobs and its noise tables' (noise: sensors -> noise_jobs()), `workers`
    processes at a time, and write path, the card's measured JSON: {setup: [eval JSON of each
    run]}, and under "noise" {sensors: {setup: [eval JSON]}}."""
    import json

    noisy = [job for part in noise.values() for job in part]
    results = evaluate_jobs(jobs + noisy, workers)
    measured: dict = by_setup(jobs, results[: len(jobs)])
    measured["noise"], done = {}, len(jobs)
    for sensors_name, part in noise.items():
        measured["noise"][sensors_name] = by_setup(part, results[done : done + len(part)])
        done += len(part)
    path.write_text(json.dumps(measured, indent=1))
    return path


def render_card(template: Path, values: dict[str, str]) -> str:
    """A card's text: its template (train/NAME/card.md, string.Template: ${name} where a
    measured value goes) filled from the measured values, each already formatted."""
    from string import Template

    return Template(template.read_text()).substitute(values)


def split_sizes() -> dict[str, str]:
    """The clips in each part of the split, as every card's Data section names them."""
    from ..data.catalog import load_split

    split = load_split()
    return {f"len_split_{part}": str(len(split[part])) for part in ("train", "validation", "test")}
