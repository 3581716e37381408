"""An evaluation's results: each clip's metrics per estimator (EvalResult, what `eval
--output` writes and model cards read), their bootstrap intervals and the tables printed of
them. Kept below apps/ so that what reads results (the model cards, `view`) need not import
the evaluation that makes them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from .metrics import weighted_mean


class Clip(Protocol):
    """What a result records of a clip (evaluation.EvalItem is one)."""

    name: str
    key: str
    group: str
    source: str
    subject: str
    category: str


@dataclass
class EvalResult:
    estimator: str
    sensors: str
    split: str
    clips: list[str] = field(default_factory=list)
    frames: list[int] = field(default_factory=list)
    per_clip: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0
    protocol: str = "field"
    keys: list[str] = field(default_factory=list)
    groups: list[str] = field(default_factory=list)
    sources: list[str] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)
    settings: dict = field(default_factory=dict)  # what a resumed run must share
    protocol_spec: dict = field(default_factory=dict)  # Protocol.to_json(): what `view` re-runs
    subjects: list[str] = field(default_factory=list)  # each clip's person, where known
    categories: list[str] = field(default_factory=list)  # each clip's kind of motion, where known
    options: dict = field(default_factory=dict)  # every option of the method, as run (method_options)

    @property
    def summary(self) -> dict[str, float]:
        return weighted_mean(self.per_clip, self.frames) if self.per_clip else {}

    def add(self, item: Clip, frames: int, metrics: dict[str, float]) -> None:
        self.clips.append(item.name)
        self.frames.append(frames)
        self.per_clip.append(metrics)
        self.keys.append(item.key)
        self.groups.append(item.group)
        self.sources.append(item.source)
        self.subjects.append(item.subject)
        self.categories.append(item.category)

    def by_group(self, by: str = "group") -> dict[str, EvalResult]:
        """The clips of each group (by="group": folder or prefix; by="subject": person;
        by="category": kind of motion)."""
        out: dict[str, EvalResult] = {}
        keys = {"group": self.groups, "subject": self.subjects, "category": self.categories}[by]
        for k, group in enumerate(keys if len(keys) == len(self.clips) else []):
            if group:
                part = out.setdefault(
                    group, EvalResult(self.estimator, self.sensors, self.split, protocol=self.protocol)
                )
                part.clips.append(self.clips[k])
                part.frames.append(self.frames[k])
                part.per_clip.append(self.per_clip[k])
        return dict(sorted(out.items()))

    def to_json(self, intervals: bool = True) -> dict:
        """intervals=False: without the bootstrap intervals (a run's in-between writes, which
        would otherwise redo 1000 draws per group after every clip)."""
        interval = clip_interval if intervals else (lambda *_, **__: {})
        clips = [{"clip": c, "frames": n, **m} for c, n, m in zip(self.clips, self.frames, self.per_clip, strict=True)]
        extras = (
            ("key", self.keys),
            ("group", self.groups),
            ("source", self.sources),
            ("subject", self.subjects),
            ("category", self.categories),
        )
        for extra, values in extras:
            if len(values) == len(clips):
                for row, v in zip(clips, values, strict=True):
                    row[extra] = v
        groups = {
            g: {
                "clips": len(r.clips),
                "frames": int(sum(r.frames)),
                "summary": r.summary,
                "interval_95": interval(r.per_clip, r.frames),
            }
            for g, r in self.by_group().items()
        }
        return {
            "estimator": self.estimator,
            "sensors": self.sensors,
            "split": self.split,
            "protocol": self.protocol,
            "settings": self.settings,
            "options": self.options,
            "protocol_spec": self.protocol_spec,
            "frames": int(sum(self.frames)),
            "seconds": self.seconds,
            "summary": self.summary,
            "interval_95": interval(self.per_clip, self.frames),
            "interval_95_by_subject": interval(self.per_clip, self.frames, units=self.subject_units()),
            "groups": groups,
            "skipped": self.skipped,
            "clips": clips,
        }

    def subject_units(self) -> list[str] | None:
        """Each clip's person, where every clip has one and there are two people or more."""
        if len(self.subjects) != len(self.clips) or not all(self.subjects) or len(set(self.subjects)) < 2:
            return None
        return self.subjects

    @classmethod
    def from_json(cls, data: dict) -> EvalResult:
        info = ("clip", "frames", "key", "group", "source", "subject", "category")
        rows = data.get("clips", [])
        return cls(
            data["estimator"],
            data["sensors"],
            data["split"],
            [r["clip"] for r in rows],
            [int(r["frames"]) for r in rows],
            [{k: v for k, v in r.items() if k not in info} for r in rows],
            float(data.get("seconds", 0.0)),
            data.get("protocol", "field"),
            [r.get("key", r["clip"]) for r in rows],
            [r.get("group", "") for r in rows],
            [r.get("source", "") for r in rows],
            list(data.get("skipped", [])),
            dict(data.get("settings", {})),
            dict(data.get("protocol_spec", {})),  # absent from files written before it
            [r.get("subject", "") for r in rows],
            [r.get("category", "") for r in rows],  # absent from files written before it
            dict(data.get("options", {})),  # absent from files written before it
        )


def clip_interval(
    per_clip: list[dict[str, float]],
    frames: list[int],
    draws: int = 1000,
    seed: int = 0,
    units: list[str] | None = None,
) -> dict[str, list[float]]:
    """A 95 % bootstrap interval of each frame-weighted mean, clips drawn with replacement
    (how far the figure could move with other clips of the same kind); none under 2 clips.
    units: each clip's person, to draw people with all their clips instead (how far it could
    move with other people: wider, as a person's clips move together); none without units."""
    if len(per_clip) < 2 or (units is not None and len(set(units)) < 2):
        return {}
    keys = list(per_clip[0])
    values = np.array([[row.get(k, np.nan) for k in keys] for row in per_clip], dtype=float)
    weights = np.asarray(frames, dtype=float)[:, None] * np.isfinite(values)
    values = np.nan_to_num(values)
    if units is not None:  # one row per person: the sums of their clips
        names = sorted(set(units))
        member = np.array([[u == n for u in units] for n in names], dtype=float)
        values, weights = member @ (values * weights), member @ weights
        with np.errstate(invalid="ignore", divide="ignore"):
            values = np.nan_to_num(values / weights)
    picks = np.random.default_rng(seed).integers(0, len(values), (draws, len(values)))
    with np.errstate(invalid="ignore", divide="ignore"):
        means = (values * weights)[picks].sum(1) / weights[picks].sum(1)
    out = {}
    for j, key in enumerate(keys):
        ok = np.isfinite(means[:, j])
        if ok.any():
            out[key] = [float(np.percentile(means[ok, j], 2.5)), float(np.percentile(means[ok, j], 97.5))]
    return out


def format_table(
    results: list[EvalResult],
    reference: dict[str, dict[str, float]] | None = None,
    max_width: int = 100,
    intervals: bool = False,
) -> str:
    """Metrics as rows, one column per result (and per paper figure given in reference).
    Columns whose names would make the table wider than max_width are numbered, and the
    numbers named below the table, so it fits a normal terminal. intervals: each mean with
    its 95 % bootstrap intervals, clips drawn and (with two people or more) people drawn."""
    mixed = len({r.protocol for r in results}) > 1
    columns = [f"{r.estimator}/{r.sensors}" + (f" ({r.protocol})" if mixed else "") for r in results] + list(
        reference or {}
    )
    values = [r.summary for r in results] + list((reference or {}).values())
    keys = list(results[0].summary)
    width = max(len(k) for k in keys) + 2
    colw = max(12, *(len(c) + 2 for c in columns))
    legend = []
    if width + colw * len(columns) > max_width:
        legend = [f"  [{k + 1}] {c}" for k, c in enumerate(columns)]
        columns = [f"[{k + 1}]" for k in range(len(columns))]
        colw = 9
    bounds: list[tuple[dict, dict]] = []
    if intervals:
        for r in results:
            units = r.subject_units()
            by_person = clip_interval(r.per_clip, r.frames, units=units) if units is not None else {}
            bounds.append((clip_interval(r.per_clip, r.frames), by_person))
        colw = max(colw, 34 if any(b[1] for b in bounds) else 22)
    lines = ["".ljust(width) + "".join(c.rjust(colw) for c in columns)]
    for key in keys:
        cells = []
        for k, v in enumerate(values):
            x = v.get(key, float("nan"))
            text = "-" if not np.isfinite(x) else f"{x:.2f}"
            for found in bounds[k] if k < len(bounds) and np.isfinite(x) else ():
                if key in found and np.all(np.isfinite(found[key])):
                    text += f" [{found[key][0]:.2f}, {found[key][1]:.2f}]"
            cells.append(text.rjust(colw))
        lines.append(key.ljust(width) + "".join(cells))
    if intervals:
        lines.append("(mean [95 % interval, clips drawn] [95 % interval, people drawn], by bootstrap)")
    frames = sum(results[0].frames)
    where = "the motion files given" if results[0].split == "files" else f"the {results[0].split} split"
    protocol = "protocols as named" if mixed else f"{results[0].protocol} protocol"
    lines.append(f"({len(results[0].clips)} clips of {where}, {frames} frames; {protocol})")
    return "\n".join(lines + _intervals(results) + legend)


def _intervals(results: list[EvalResult], metric: str = "MPJPE [cm]") -> list[str]:
    """The headline metric's 95 % bootstrap intervals, clips drawn and people drawn, a line a
    result: how far each mean could move with other clips, or other people."""
    lines = []
    for r in results:
        mean = r.summary.get(metric, float("nan"))
        by_clip = clip_interval(r.per_clip, r.frames).get(metric)
        if not np.isfinite(mean) or not by_clip:
            continue
        text = f"  {r.estimator}/{r.sensors}: {mean:.2f}, 95 % interval [{by_clip[0]:.2f}, {by_clip[1]:.2f}] by clip"
        units = r.subject_units()
        if units is not None and (by_person := clip_interval(r.per_clip, r.frames, units=units).get(metric)):
            text += f", [{by_person[0]:.2f}, {by_person[1]:.2f}] by person ({len(set(units))} people)"
        lines.append(text)
    return [f"{metric}, bootstrap:"] + lines if lines else []


def format_groups(
    results: list[EvalResult],
    metric: str = "MPJPE [cm]",
    label: str = "group",
    by: str = "group",
    notes: dict[str, str] | None = None,
) -> str:
    """One metric by group (by="group": folder or actor prefix; by="subject": person;
    by="category": kind of motion): the frame-weighted mean of each result with its 95 %
    clip-bootstrap interval, and the group's clip count; notes: a word after a group's name."""
    parts = [r.by_group(by) for r in results]
    names = sorted({g for p in parts for g in p})
    if not names:
        return ""
    columns = [f"{r.estimator}/{r.sensors}" for r in results]
    notes = notes or {}
    named = {g: f"{g}{notes.get(g, '')} ({max(len(p[g].clips) for p in parts if g in p)} clips)" for g in names}
    width = max(len(label) + len(metric) + 5, *(len(n) + 1 for n in named.values()))
    colw = max(22, *(len(c) + 2 for c in columns))
    lines = [f"{metric} by {label}".ljust(width) + "".join(c.rjust(colw) for c in columns)]
    for g in names:
        cells = []
        for p in parts:
            r = p.get(g)
            mean = r.summary.get(metric, float("nan")) if r else float("nan")
            interval = clip_interval(r.per_clip, r.frames).get(metric) if r else None
            text = "-" if not np.isfinite(mean) else f"{mean:.2f}"
            if interval and np.isfinite(mean):
                text += f" [{interval[0]:.2f}, {interval[1]:.2f}]"
            cells.append(text.rjust(colw))
        lines.append(named[g].ljust(width) + "".join(cells))
    lines.append("(frame-weighted mean [95 % interval, clips drawn with replacement])")
    if by == "category":
        lines += _worst_against_ik(results, parts, names, metric)
    return "\n".join(lines)


def _worst_against_ik(results: list[EvalResult], parts: list[dict], kinds: list[str], metric: str) -> list[str]:
    """For each estimator beside IK (the same sensors): its worst kind's share of IK's figure,
    the kind a default must hold on (issue 73)."""
    ik = next((k for k, r in enumerate(results) if r.estimator.partition(":")[0] == "ik"), None)
    if ik is None or len(kinds) < 2:
        return []
    out = []
    for k, r in enumerate(results):
        if k == ik or r.sensors != results[ik].sensors:
            continue
        shares = {}
        for g in kinds:
            mine, base = parts[k].get(g), parts[ik].get(g)
            if mine is None or base is None:
                continue
            a, b = mine.summary.get(metric, float("nan")), base.summary.get(metric, float("nan"))
            if np.isfinite(a) and np.isfinite(b) and b > 0:
                shares[g] = a / b
        if shares:
            worst = max(shares, key=shares.__getitem__)
            out.append(f"  {r.estimator}/{r.sensors}: worst kind {worst}, {shares[worst]:.2f}x IK's {metric}")
    return out
