"""The runtime (nodes, offline tools, demo) needs ONNX Runtime, never torch: `make demo`
installs requirements.txt alone, and torch comes only with the training extra."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_runtime_never_imports_torch_or_the_training_packages(tmp_path):
    script = textwrap.dedent(f"""
        import sys
        from sparse_body.cli import main
        out = {str(tmp_path)!r}
        runs = [["make-bag", out + "/six", "--seconds", "1", "--sensors", "six_point"],
                ["process", out + "/six", out + "/ik", "--quiet"],
                ["process", out + "/six", out + "/dtp", "--estimator", "dtp", "--quiet"],
                ["process", out + "/six", out + "/dragposer", "--estimator", "dragposer", "--quiet"],
                ["process", out + "/six", out + "/lobstr", "--estimator", "lobstr", "--sensors", "four_point",
                 "--quiet"],
                ["process", out + "/six", out + "/jlm", "--estimator", "avatarjlm", "--sensors", "three_point",
                 "--quiet"],
                ["demo", "--out", out + "/demo", "--seconds", "1"]]
        for argv in runs:
            try:
                main(argv)
            except SystemExit as ended:
                assert ended.code in (0, None), (argv, ended.code)
        try:
            import sparse_body.ros.estimator_node, sparse_body.ros.tracker_bridge_node, sparse_body.ros.constraint_node
        except ImportError:
            pass                     # no ROS here: the ROS-free runtime is what is checked
        print("IMPORTED:", sorted(m for m in ("torch", "roma", "onnx") if m in sys.modules))
    """)
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, "SPARSE_BODY_CACHE": str(tmp_path / "cache")},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "IMPORTED: []" in done.stdout, done.stdout[-2000:]


def test_the_runtime_requirements_leave_training_out():
    runtime = (ROOT / "requirements.txt").read_text()
    names = {
        line.split(">")[0].split("=")[0].split("<")[0].strip()
        for line in runtime.splitlines()
        if line.strip() and not line.startswith("#")
    }
    assert not names & {"torch", "roma", "onnx", "pytest", "hypothesis", "atheris"}, names
    assert "onnxruntime" in names
    training = (ROOT / "requirements-train.txt").read_text()
    assert "torch" in training
