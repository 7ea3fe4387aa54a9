"""deploy/kubernetes: the Indexed Job manifest says what its pods need, and its entry script,
run here as two pods would be (JOB_COMPLETION_INDEX 0 and 1) with the manifest's own list,
arguments and environment, relights the entry its index names and exits with the codes the
manifest's podFailurePolicy expects."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import yaml
from conftest import ROOT, lsydrelight

DEPLOY = ROOT / "deploy" / "kubernetes"
OPT = "/opt/lsydrelight"


def manifest() -> tuple[dict, dict]:
    docs = {d["kind"]: d for d in yaml.safe_load_all((DEPLOY / "relight-job.yaml").read_text())}
    return docs["Job"], docs["ConfigMap"]


def entries(list_text: str) -> list[str]:
    return [line for line in list_text.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def test_the_job_runs_one_pod_per_listed_recording_and_fails_bad_ones_without_retry() -> None:
    job, config = manifest()
    spec = job["spec"]
    assert spec["completionMode"] == "Indexed"
    (list_name,) = config["data"]
    assert spec["completions"] == len(entries(config["data"][list_name])), "completions = entries in the list"
    assert spec["backoffLimitPerIndex"] >= 1
    pod = spec["template"]["spec"]
    assert pod["restartPolicy"] == "Never", "podFailurePolicy requires restartPolicy Never"
    (container,) = pod["containers"]
    assert Path(container["command"][0]).name == "relight-index.sh"

    rules = spec["podFailurePolicy"]["rules"]
    fail_index = [r for r in rules if r["action"] == "FailIndex"]
    assert len(fail_index) == 1
    codes = fail_index[0]["onExitCodes"]
    assert codes["containerName"] == container["name"] and codes["operator"] == "In"
    assert sorted(codes["values"]) == [1, 2], "bad input (1) and usage (2) fail the index at once"
    assert any(r["action"] == "Ignore" and r["onPodConditions"][0]["type"] == "DisruptionTarget" for r in rules), (
        "an evicted pod is not counted against its index"
    )

    # The list the script reads is the ConfigMap's, where the pod mounts it.
    env = {e["name"]: e["value"] for e in container["env"]}
    mounts = {m["name"]: m["mountPath"] for m in container["volumeMounts"]}
    volumes = {v["name"]: v for v in pod["volumes"]}
    config_name = config["metadata"]["name"]
    list_volume = next(n for n, v in volumes.items() if v.get("configMap", {}).get("name") == config_name)
    assert env["LSYDRELIGHT_LIST"] == f"{mounts[list_volume]}/{list_name}"
    script = (DEPLOY / "relight-index.sh").read_text()
    for name in ["LSYDRELIGHT_LIST", "LSYDRELIGHT_CALLS", "LSYDRELIGHT_OUT"]:
        assert name in env and name in script, name
    for name, path in env.items():
        if path.startswith("/calls"):
            assert any(path.startswith(m) for m in mounts.values()), f"{name} {path} is on no volume"


def tiny_recording(path: Path) -> None:
    subprocess.run(
        ["gst-launch-1.0", "-q", "videotestsrc", "num-buffers=8", "!", "video/x-raw,width=160,height=120"]
        + ["!", "x264enc", "!", "mp4mux", "!", "filesink", f"location={path}"],
        check=True,
    )


def pod(index: str | None, list_file: Path, calls: Path, out: Path, tmp_path: Path) -> subprocess.CompletedProcess:
    """The entry script as the manifest runs it: its arguments and environment, with the
    image's /opt/lsydrelight standing for this checkout."""
    job, _ = manifest()
    container = job["spec"]["template"]["spec"]["containers"][0]
    here = {
        f"{OPT}/models": str(ROOT / "models"),
        f"{OPT}/libonnxruntime.so": str(ROOT / "target" / "onnxruntime" / "libonnxruntime.so"),
    }

    def local(value: str) -> str:
        for image_path, checkout_path in here.items():
            value = value.replace(image_path, checkout_path)
        return value

    env = {**os.environ, **{e["name"]: local(e["value"]) for e in container["env"]}}
    env.update(LSYDRELIGHT_LIST=str(list_file), LSYDRELIGHT_CALLS=str(calls), LSYDRELIGHT_OUT=str(out))
    env["LSYDRELIGHT"] = str(lsydrelight())
    env.pop("JOB_COMPLETION_INDEX", None)
    if index is not None:
        env["JOB_COMPLETION_INDEX"] = index
    args = [local(a) for a in container["args"]]
    return subprocess.run(
        [str(DEPLOY / "relight-index.sh"), *args], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120
    )


def test_each_pod_relights_the_entry_its_index_names(tmp_path: Path) -> None:
    _, config = manifest()
    (list_name,) = config["data"]
    list_file = tmp_path / list_name
    list_file.write_text(config["data"][list_name])
    first, second = entries(config["data"][list_name])[:2]
    calls, out = tmp_path / "calls", tmp_path / "relit"
    calls.mkdir()
    tiny_recording(calls / first)
    (calls / second).write_text("not a recording\n")

    relit = pod("0", list_file, calls, out, tmp_path)
    assert relit.returncode == 0, relit.stderr
    assert (out / first).stat().st_size > 0
    assert f"ok {first}: 8 frames in" in " ".join(relit.stdout.split())

    broken = pod("1", list_file, calls, out, tmp_path)
    assert broken.returncode == 1, "bad input: the code the Job fails the index on"
    assert second in broken.stderr
    assert not list(out.glob(Path(second).stem + "*"))

    beyond = pod("3", list_file, calls, out, tmp_path)
    assert beyond.returncode == 2 and "no entry 3 (it has 3)" in beyond.stderr
    unset = pod(None, list_file, calls, out, tmp_path)
    assert unset.returncode == 2 and "Indexed Job" in unset.stderr


def test_a_tab_pairs_a_face_recording_with_its_screen_recording(tmp_path: Path) -> None:
    calls, out = tmp_path / "calls", tmp_path / "relit"
    calls.mkdir()
    tiny_recording(calls / "face.mp4")
    tiny_recording(calls / "screen.mp4")
    list_file = tmp_path / "list.txt"
    list_file.write_text("# one call\n\nface.mp4\tscreen.mp4\n")
    relit = pod("0", list_file, calls, out, tmp_path)
    assert relit.returncode == 0, relit.stderr
    assert (out / "face.mp4").stat().st_size > 0
    missing = tmp_path / "missing.txt"
    missing.write_text(f"face.mp4\t{calls / 'nowhere.mp4'}\n")
    absent = pod("0", missing, calls, out, tmp_path)
    assert absent.returncode == 1 and "--screen" in absent.stderr and "nowhere.mp4" in absent.stderr
