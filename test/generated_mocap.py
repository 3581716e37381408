"""Small ASF/AMC files in CMU's bone layout (what the retargeter maps), written by the tests
the way other labs' distributions lay them out; nothing here needs ../shared."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np

# name, parent, direction (y up, the actor faces +z, +x is their left), length (m), dof
BONES = [
    ("lhipjoint", "root", (1, -0.8, 0), 0.10, ""),
    ("lfemur", "lhipjoint", (0, -1, 0), 0.42, "rx ry rz"),
    ("ltibia", "lfemur", (0, -1, 0), 0.42, "rx"),
    ("lfoot", "ltibia", (0, -0.3, 1), 0.14, "rx rz"),
    ("ltoes", "lfoot", (0, 0, 1), 0.05, "rx"),
    ("lowerback", "root", (0, 1, 0), 0.12, "rx ry rz"),
    ("upperback", "lowerback", (0, 1, 0), 0.12, "rx ry rz"),
    ("thorax", "upperback", (0, 1, 0), 0.12, "rx ry rz"),
    ("lowerneck", "thorax", (0, 1, 0), 0.08, "rx ry rz"),
    ("upperneck", "lowerneck", (0, 1, 0), 0.08, "rx ry rz"),
    ("head", "upperneck", (0, 1, 0), 0.10, "rx ry rz"),
    ("lclavicle", "thorax", (1, 0.2, 0), 0.15, "ry rz"),
    ("lhumerus", "lclavicle", (1, 0, 0), 0.28, "rx ry rz"),
    ("lradius", "lhumerus", (1, 0, 0), 0.25, "rx"),
    ("lwrist", "lradius", (1, 0, 0), 0.01, "ry"),
    ("lhand", "lwrist", (1, 0, 0), 0.08, "rx rz"),
]
BONES += [
    (
        "r" + n[1:],
        p if p in ("root", "lowerback", "thorax") or not p.startswith("l") else "r" + p[1:],
        (-d[0], d[1], d[2]),
        length,
        dof,
    )
    for n, p, d, length, dof in BONES
    if n.startswith("l") and n not in ("lowerback", "lowerneck")
]
ROOT_HEIGHT = 0.99  # the toes' joint about 4 cm above the floor with the legs straight


def asf(scale: float = 1.0, name: str = "actor") -> str:
    """An actor's skeleton; scale lengthens every bone (another, taller actor)."""
    text = f":version 1.10\n:name {name}\n:units\n  mass 1.0\n  length 0.0254\n  angle deg\n"  # 1 unit = 1 m
    text += ":root\n  order TX TY TZ RX RY RZ\n  axis XYZ\n  position 0 0 0\n  orientation 0 0 0\n:bonedata\n"
    for k, (bone, _, direction, length, dof) in enumerate(BONES, 1):
        d = np.asarray(direction, float) / np.linalg.norm(direction)
        text += (
            f"  begin\n    id {k}\n    name {bone}\n    direction {d[0]:.6f} {d[1]:.6f} {d[2]:.6f}\n"
            f"    length {length * scale:.6f}\n    axis 0 0 0 XYZ\n" + (f"    dof {dof}\n" if dof else "") + "  end\n"
        )
    children: dict[str, list[str]] = {}
    for bone, parent, *_ in BONES:
        children.setdefault(parent, []).append(bone)
    return text + ":hierarchy\n  begin\n" + "".join(f"    {p} {' '.join(c)}\n" for p, c in children.items()) + "  end\n"


def amc(frames: int = 120, seed: int = 0, fps: float = 120.0) -> str:
    """A walk on the spot drifting forward: legs and arms swinging (each clip its own phase)."""
    rng = np.random.default_rng(seed)
    phase, speed = rng.uniform(0, 2 * np.pi), rng.uniform(0.3, 0.8)
    lines = [":FULLY-SPECIFIED", ":DEGREES"]
    for f in range(frames):
        t = f / fps
        swing = 20 * np.sin(2 * np.pi * t + phase)
        lines.append(str(f + 1))
        lines.append(f"root 0 {ROOT_HEIGHT:.4f} {speed * t:.4f} 0 {5 * np.sin(t):.3f} 0")
        for bone, _, _, _, dof in BONES:
            if not dof:
                continue
            values = {"rx": 0.0, "ry": 0.0, "rz": 0.0}
            if bone in ("lfemur", "rfemur"):
                values["rx"] = swing if bone[0] == "l" else -swing
            if bone in ("ltibia", "rtibia"):
                values["rx"] = max(0.0, swing if bone[0] == "l" else -swing)
            if bone in ("lhumerus", "rhumerus"):
                values["rz"] = -70 if bone[0] == "l" else 70  # arms down
                values["rx"] = -swing / 2 if bone[0] == "l" else swing / 2
            lines.append(bone + " " + " ".join(f"{values[d]:.3f}" for d in dof.split()))
    return "\n".join(lines) + "\n"


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def by_motion_class(root: Path, frames: int = 120) -> Path:
    """Another lab's layout: a folder per motion class, every actor's ASF in each, an upper-case
    .AMC, and stray files a download brings along."""
    for group, takes in (
        ("walk", ["actorA_walk01", "actorA_walk02", "actorB_walk01"]),
        ("run", ["actorA_run01", "actorB_run01"]),
    ):
        write(root / group / "actorA.asf", asf(1.0, "actorA"))
        write(root / group / "actorB.asf", asf(1.05, "actorB"))
        for take in takes:
            suffix = ".AMC" if take == "actorB_walk01" else ".amc"
            write(root / group / (take + suffix), amc(frames, seed=zlib.crc32(take.encode())))
        write(root / group / ".DS_Store", "\0\0binary")
        write(root / group / "notes.mat", "MATLAB 5.0")
    return root
