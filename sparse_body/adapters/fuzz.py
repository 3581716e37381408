"""`python -m sparse_body.adapters.fuzz {serial,vmc} RUNS`: coverage-guided fuzzing (atheris,
libFuzzer) of the two parsers that read bytes from outside.

The corpus starts from well-formed input (serial frames of both kinds, VMC messages of each
tracking address, a bundle) that libFuzzer then mutates. serial: the input is split into
reads of sizes taken from the input itself and fed to one FrameDecoder, as a stream with
garbage and torn frames. vmc: the input is one UDP datagram. Any exception escaping a
decoder, or a decoded sample that is not a finite unit-quaternion pose, stops the run with
a crash report and a non-zero exit status; a clean run prints how many inputs it executed.
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import atheris

with atheris.instrument_imports():
    import numpy as np
    from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
    from pythonosc.osc_message_builder import OscMessageBuilder

    from sparse_body.adapters.serial_protocol import FrameDecoder, encode_frame
    from sparse_body.adapters.vmc import KINDS, VmcDecoder


def _check(orientation, position) -> None:
    if not (np.all(np.isfinite(orientation)) and abs(np.linalg.norm(orientation) - 1) < 1e-6):
        raise AssertionError(f"decoded a bad orientation {orientation}")
    if position is not None and not np.all(np.isfinite(position)):
        raise AssertionError(f"decoded a bad position {position}")


_serial = FrameDecoder()
_vmc = VmcDecoder()


def serial_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    cuts = [fdp.ConsumeIntInRange(1, 64) for _ in range(fdp.ConsumeIntInRange(1, 4))]
    rest = fdp.ConsumeBytes(fdp.remaining_bytes())
    i = k = 0
    while i < len(rest):
        for frame in _serial.feed(rest[i:i + cuts[k % len(cuts)]]):
            _check(frame.orientation, frame.position)
        i, k = i + cuts[k % len(cuts)], k + 1


def vmc_input(data: bytes) -> None:
    for sample in _vmc.datagram(data, 0.0):
        _check(sample.orientation, sample.position)


def seeds() -> list[bytes]:
    out = [encode_frame(1, 1000, [0, 0, 0, 1]), encode_frame(2, 2 ** 32 - 5, [0.5, 0.5, 0.5, 0.5], [1, 2, 3])]
    out.append(b"\x02\x01" + out[0] + b"\xa5\x5a\x01" + out[1])
    for address in KINDS:
        b = OscMessageBuilder(address)
        for v in ["LHR-1", 0.1, 1.6, 0.2, 0.0, 0.0, 0.0, 1.0]:
            b.add_arg(v)
        out.append(b.build().dgram)
    bundle = OscBundleBuilder(IMMEDIATELY)
    bundle.add_content(OscMessageBuilder("/VMC/Ext/Hmd/Pos").build())
    out.append(bundle.build().dgram)
    return out


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv if argv is None else argv)
    if len(argv) < 3 or argv[1] not in ("serial", "vmc"):
        sys.exit("usage: python -m sparse_body.adapters.fuzz {serial,vmc} RUNS [libFuzzer flags]")
    target, runs = argv[1], int(argv[2])
    corpus = Path(tempfile.mkdtemp(prefix=f"sparse_body_fuzz_{target}_"))
    for i, seed in enumerate(seeds()):
        (corpus / f"seed{i}").write_bytes(seed)
    # -timeout: an input that takes seconds is a hang (a receiver thread stuck for good)
    atheris.Setup([argv[0], f"-runs={runs}", "-max_len=512", "-timeout=10", *argv[3:], str(corpus)],
                  serial_input if target == "serial" else vmc_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
