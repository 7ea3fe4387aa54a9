"""lsyd.batch_ray on a local Ray instance: one task per recording through the real
`lsydrelight relight`, results gathered, a bad recording reported once with its exit code,
and a command killed by a signal retried only as often as asked."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from conftest import ROOT, lsydrelight

FRAMES = 12


def tiny_recording(path: Path, muxer: str) -> None:
    subprocess.run(
        [
            "gst-launch-1.0",
            "-q",
            "videotestsrc",
            f"num-buffers={FRAMES}",
            "!",
            "video/x-raw,width=160,height=120,framerate=30/1",
            "!",
            "x264enc",
            "!",
            muxer,
            "!",
            "filesink",
            f"location={path}",
        ],
        check=True,
    )


def test_each_recording_is_a_task_and_a_bad_one_is_reported_not_retried(tmp_path: Path) -> None:
    calls = tmp_path / "calls"
    calls.mkdir()
    for name, muxer in [("monday.mp4", "mp4mux"), ("tuesday.mkv", "matroskamux"), ("wednesday.mp4", "mp4mux")]:
        tiny_recording(calls / name, muxer)
    (calls / "broken.mp4").write_text("not a recording\n")
    # A recording whose command the "node" kills, as the out-of-memory killer would.
    tiny_recording(calls / "killed.mp4", "mp4mux")

    attempts = tmp_path / "attempts.log"
    wrapper = tmp_path / "lsydrelight"
    wrapper.write_text(
        "#!/bin/sh\n"
        f'echo "$3" >> {attempts}\n'
        'case "$3" in *killed.mp4) kill -KILL $$ ;; esac\n'
        f'cd {ROOT} && exec {lsydrelight()} "$@"\n'
    )
    wrapper.chmod(0o755)

    out = tmp_path / "relit"
    report = tmp_path / "results.json"
    proc = subprocess.run(
        [sys.executable, "-m", "lsyd.batch_ray", "--face", str(calls), "--out", str(out)]
        + ["--cpus-per-task", "1", "--max-retries", "1", "--lsydrelight", str(wrapper), "--json", str(report)],
        cwd=ROOT / "train",
        capture_output=True,
        text=True,
        timeout=180,
    )
    print(proc.stdout, proc.stderr)
    assert proc.returncode == 1, "a failed recording fails the run"
    results = {Path(r["face"]).name: r for r in json.loads(report.read_text())}
    assert sorted(results) == ["broken.mp4", "killed.mp4", "monday.mp4", "tuesday.mkv", "wednesday.mp4"]

    for name in ["monday.mp4", "tuesday.mkv", "wednesday.mp4"]:
        r = results[name]
        assert r["exit_code"] == 0, r
        assert r["frames"] == FRAMES and r["fps"] > 0 and r["seconds"] > 0, r
        assert (out / name).stat().st_size > 0
        assert f"ok      {name}: {FRAMES} frames in" in proc.stdout

    broken = results["broken.mp4"]
    assert broken["exit_code"] == 1, broken
    assert "broken.mp4" in broken["error"], broken
    assert not (out / "broken.mp4").exists()
    assert "failed  broken.mp4: exit 1" in proc.stdout

    killed = results["killed.mp4"]
    assert killed["exit_code"] is None and "signal 9" in killed["error"], killed

    tries = [Path(line).name for line in attempts.read_text().split()]
    assert tries.count("broken.mp4") == 1, "a bad input is not retried"
    assert tries.count("killed.mp4") == 2, "a system failure is retried --max-retries times, no more"
    assert "3 of 5 relit" in proc.stdout
