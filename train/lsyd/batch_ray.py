"""Relight many recorded calls on a Ray cluster: one task per recording.

Each task runs ``lsydrelight relight --face FILE --out FILE ...`` on whichever machine Ray
gives it; a recording is one job because the element's temporal state needs the whole call
in one process. Ray does the scheduling; this driver only submits, gathers and reports::

    python -m lsyd.batch_ray --face calls/ --out relit/ [--screen screens/] [--address auto] \\
        [--cpus-per-task 2] [--max-retries 2] [--lsydrelight PATH] [-- --target sunset.png ...]

Inputs and outputs must be on storage every node sees under the same path (NFS, a shared
volume), and every node needs ``lsydrelight`` (``cargo install --locked --path cli``), the
model and the ONNX Runtime library (``--model``, ``LSYDRELIGHT_ORT_LIBRARY``; arguments after
``--`` go to every ``lsydrelight relight``). Without ``--address`` a local Ray instance is
started on this machine; ``--address auto`` joins the cluster this node belongs to.

A recording the command rejects (exit 1: bad input or a failed run; 2: usage) is reported
once with the command's own error and not retried: it would fail again. Only a system
failure is retried, at most ``--max-retries`` times: the worker or its node died, or the
command was killed by a signal (the out-of-memory killer, a node shutting down).
One line per recording says its result, time and speed; the exit status is 0 when every
recording was relit, 1 otherwise, 130 on Ctrl-C (the tasks are cancelled).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

# What `lsydrelight relight --face DIR` relights (cli/src/relight/folder.rs).
RECORDING_EXTENSIONS = {".mp4", ".mkv", ".mov", ".webm", ".avi", ".m4v", ".ts", ".y4m", ".ogv"}
# The containers `lsydrelight relight` writes; any other input becomes MKV.
OUTPUT_CONTAINERS = {".mp4", ".mkv"}
# The command's summary line: "ok face.mp4: 300 frames in 5.2 s, 57.7 fps -> relit.mp4".
RATE = re.compile(r"(\d+) frames in ([\d.]+) s, ([\d.]+) fps")


class SystemFailure(RuntimeError):
    """The command did not end by itself (killed by a signal): worth another try."""


@dataclass
class Result:
    face: str
    out: str
    exit_code: int | None
    seconds: float
    frames: int | None = None
    fps: float | None = None
    error: str = ""
    node: str = ""

    @property
    def ok(self) -> bool:
        return self.exit_code == 0

    def line(self) -> str:
        name = Path(self.face).name
        where = f" (on {self.node})" if self.node else ""
        if self.ok:
            speed = f"{self.frames} frames in {self.seconds:.1f} s, {self.fps:.1f} fps" if self.frames else ""
            return f"ok      {name}: {speed} -> {self.out}{where}"
        code = "no exit code" if self.exit_code is None else f"exit {self.exit_code}"
        return f"failed  {name}: {code} after {self.seconds:.1f} s: {self.error}{where}"


def relight_command(binary: str, face: Path, out: Path, screen: Path | None, extra: list[str]) -> list[str]:
    command = [binary, "relight", "--face", str(face), "--out", str(out)]
    if screen is not None:
        command += ["--screen", str(screen)]
    return command + extra


def relight_one(binary: str, face: str, out: str, screen: str | None, extra: list[str]) -> Result:
    """One recording through ``lsydrelight relight``, on whichever node runs it."""
    import socket

    started = time.monotonic()
    command = relight_command(binary, Path(face), Path(out), Path(screen) if screen else None, extra)
    proc = subprocess.run(command, capture_output=True, text=True, env={**os.environ, "TERM": "dumb"})
    seconds = time.monotonic() - started
    node = socket.gethostname()
    if proc.returncode < 0:
        raise SystemFailure(f"{Path(face).name}: lsydrelight was killed by signal {-proc.returncode} on {node}")
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    rate = RATE.search(proc.stdout)
    return Result(
        face=face,
        out=out,
        exit_code=proc.returncode,
        seconds=seconds,
        frames=int(rate.group(1)) if rate else None,
        fps=float(rate.group(3)) if rate else None,
        error=(errors[-1].removeprefix("error: ") if errors else proc.stderr.strip()[-500:]),
        node=node,
    )


def recordings(face: Path) -> list[Path]:
    if face.is_file():
        return [face]
    if not face.is_dir():
        raise SystemExit(f"error: --face {face}: no such file or folder")
    found = sorted(p for p in face.iterdir() if p.is_file() and p.suffix.lower() in RECORDING_EXTENSIONS)
    if not found:
        raise SystemExit(f"error: --face {face}: no recordings ({' '.join(sorted(RECORDING_EXTENSIONS))})")
    return found


def output_for(face: Path, out_dir: Path) -> Path:
    suffix = face.suffix.lower()
    return out_dir / (face.stem + (suffix if suffix in OUTPUT_CONTAINERS else ".mkv"))


def screen_for(face: Path, screen_dir: Path | None) -> Path | None:
    """The screen recording with the face recording's name before its extension, if any."""
    if screen_dir is None:
        return None
    matches = [p for p in screen_dir.iterdir() if p.stem == face.stem and p.suffix.lower() in RECORDING_EXTENSIONS]
    return matches[0] if matches else None


def runtime_env() -> dict:
    """Ships this package to the workers, which run its task function."""
    return {"py_modules": [str(Path(__file__).resolve().parent)]}


def run(
    faces: list[Path],
    out_dir: Path,
    *,
    binary: str,
    screen_dir: Path | None = None,
    extra: list[str] | None = None,
    cpus_per_task: float = 2,
    max_retries: int = 2,
    report=print,
) -> list[Result]:
    """Relights every recording as its own Ray task (Ray must be initialised); reports each
    result as it comes and returns them in the order of ``faces``."""
    import ray

    task = ray.remote(num_cpus=cpus_per_task, max_retries=max_retries, retry_exceptions=[SystemFailure])(relight_one)
    pending = {}
    for face in faces:
        out = output_for(face, out_dir)
        screen = screen_for(face, screen_dir)
        screen_path = str(screen.resolve()) if screen else None
        ref = task.remote(binary, str(face.resolve()), str(out.resolve()), screen_path, extra or [])
        pending[ref] = (face, out, time.monotonic())
    results: dict[Path, Result] = {}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            face, out, submitted = pending.pop(done[0])
            try:
                result = ray.get(done[0])
            except (ray.exceptions.RayError, SystemFailure) as e:
                # Retries spent: the worker or node died, or the command was killed each time.
                cause = e.cause if isinstance(e, ray.exceptions.RayTaskError) else e
                result = Result(
                    face=str(face),
                    out=str(out),
                    exit_code=None,
                    seconds=time.monotonic() - submitted,
                    error=f"{type(cause).__name__}: {str(cause).strip().splitlines()[-1]} "
                    f"(after {max_retries} retries)",
                )
            results[face] = result
            report(result.line())
    except KeyboardInterrupt:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    return [results[f] for f in faces]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    extra: list[str] = []
    if "--" in argv:
        split = argv.index("--")
        argv, extra = argv[:split], argv[split + 1 :]
    parser = argparse.ArgumentParser(prog="python -m lsyd.batch_ray", description=__doc__.split("\n\n")[0])
    parser.add_argument("--face", type=Path, required=True, help="a recording, or a folder of them")
    parser.add_argument("--out", type=Path, required=True, help="the folder for the relit recordings")
    parser.add_argument("--screen", type=Path, help="a folder of screen recordings, paired by name")
    parser.add_argument("--address", help="a Ray cluster to join ('auto': this node's); default: start a local one")
    parser.add_argument("--cpus-per-task", type=float, default=2, help="CPUs Ray reserves per recording (default 2)")
    parser.add_argument("--max-retries", type=int, default=2, help="retries after a system failure (default 2)")
    parser.add_argument("--lsydrelight", default=None, help="the command on every node (default: lsydrelight on PATH)")
    parser.add_argument("--json", type=Path, help="also write every result to this JSON file")
    args = parser.parse_args(argv)
    binary = args.lsydrelight or shutil.which("lsydrelight") or "lsydrelight"
    faces = recordings(args.face)
    args.out.mkdir(parents=True, exist_ok=True)

    import ray

    ray.init(address=args.address, include_dashboard=False, log_to_driver=False, runtime_env=runtime_env())
    started = time.monotonic()
    try:
        results = run(
            faces,
            args.out,
            binary=binary,
            screen_dir=args.screen,
            extra=extra,
            cpus_per_task=args.cpus_per_task,
            max_retries=args.max_retries,
        )
    except KeyboardInterrupt:
        print("interrupted: the remaining tasks were cancelled", file=sys.stderr)
        return 130
    finally:
        ray.shutdown()
    failed = [r for r in results if not r.ok]
    print(f"{len(results) - len(failed)} of {len(results)} relit in {time.monotonic() - started:.1f} s")
    if args.json:
        import json

        args.json.write_text(json.dumps([asdict(r) for r in results], indent=2) + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
