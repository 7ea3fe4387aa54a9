"""The model side of the run-time against error benchmark, and its report.

    python -m lsyd.evaluation.benchmark export --data data --runs runs      # variants into target/bench-models
    python -m lsyd.evaluation.benchmark report --data data --out results/benchmark
    python -m lsyd.evaluation.benchmark network --out results/benchmark            # the network alone

``export`` exports every trained variant (width, resolution) and makes an fp16
version of the default model (the int8 one is shipped, ``models/default-int8``).
``report`` (after the element's side, ``cargo run --release --example benchmark``) measures on the validation set (what
the default configuration is chosen on) and the held-out test set with ONNX
Runtime: RMSE, MS-SSIM and FLIP against exact ground truth, the network's
time per frame at 1 and 2 threads (``network_timings``: before and after
``lsyd.optimise``'s rewrites, the shipped int8 variant, and the same network in PyTorch
eager, the peer),
and FLOPs against this machine's sustained GFLOP/s for such convolutions (the
limit). It writes ``table.md``, ``skips.md``, ``results.json`` and ``pareto.png``.
``network`` measures only the network's times, from the model folder alone, into
``network.md`` and ``network.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch
from onnx import TensorProto, helper
from skimage import data as skdata

from .. import contract, data, export, model, variants
from ..runs import hardware
from . import ROOT, metrics

BENCH = ROOT / "target" / "bench-models"
VARIANT_RUNS = ("t-lcfn", "p-r96", "p-r160", "p-w0125", "e-r96")

# The element's stats that count frames the network did not run on.
SKIP_COUNTS = ("reused-interval", "skipped-same-light", "skipped-absent", "skipped-dark")


def export_all(data_root: Path, runs: Path) -> None:
    default = ROOT / "models" / "default"
    presence = json.loads((default / "model.json").read_text())["stages"].get("presence")
    for run in VARIANT_RUNS:
        if not (runs / run / "checkpoint.pt").exists():
            print(f"skipping {run}: not trained")
            continue
        out = BENCH / run
        result = export.export(runs / run, data_root, out)
        cfg = result["config"]
        m = contract.manifest(run, cfg.net.resolution, cfg.net.widths, "fp32", {"run": run}, {})
        if presence:
            # The same presence classifier as the default model, so skips compare alike.
            shutil.copy(default / "presence.onnx", out / "presence.onnx")
            m["stages"]["presence"] = presence
        contract.write(out / "model.json", m)
    # The int8 variant the benchmark times is the shipped one (`models/default-int8`).
    variants.to_fp16(default, BENCH / "default-fp16")


def test_set_accuracy(
    folder: Path, held: data.Heldout, scores: tuple[str, ...] = tuple(metrics.SCORES)
) -> dict[str, float]:
    """RMSE, MS-SSIM and FLIP (or those named in ``scores``) of a contract model on a 9 x 9 set,
    source light known."""
    chain = contract.StageChain(folder, 2)
    codes = [chain.light_code(held.lights[j][None]) for j in range(held.lights.shape[0])]

    def relight(x: np.ndarray, _pose: int, i: int, targets: list[int]) -> np.ndarray:
        return np.concatenate([chain.relight(x[None], held.lights[i][None], codes[j]) for j in targets])

    return metrics.score_test_set(held, chain.resolution, relight, scores)


def time_ort(folder: Path, threads: int, frames: int = 60) -> float:
    """Milliseconds per frame of the network alone in ONNX Runtime (known source light)."""
    chain = contract.StageChain(folder, threads)
    r = chain.resolution
    x = np.random.default_rng(0).random((1, 3, r, r), dtype=np.float32)
    light = np.full((1, 3, 16, 32), 0.5, dtype=np.float32)
    tcode = chain.light_code(light)
    for _ in range(5):
        chain.relight(x, light, tcode)
    t = time.perf_counter()
    for _ in range(frames):
        chain.relight(x, light, tcode)
    return 1e3 * (time.perf_counter() - t) / frames


def portrait_frame(resolution: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A real face as the element gives it to the network: scikit-image's astronaut portrait,
    head and shoulders, cropped square and area-resampled to ``resolution``; a white screen and
    the portrait itself shown on the screen as the source and target lights. An int8 variant's
    ranges are calibrated on faces, and random pixels fall outside them."""
    portrait = skdata.astronaut()
    image = data.to_tensor(data.area_resize(portrait[:320, 90:410], resolution)).numpy()[None]
    white = contract.light_from_frames(np.full((90, 160, 3), 255, np.uint8))[None]
    return image, white, contract.light_from_frames(portrait)[None]


def network_timings(
    folder: Path,
    threads: tuple[int, ...] = (1, 2),
    rounds: int = 15,
    frames: int = 20,
    int8: Path | None = None,
) -> dict:
    """Milliseconds a frame of the network alone (known source light, as ``time_ort``), all in
    one run: ONNX Runtime on the model folder, ONNX Runtime on the same network exported without
    ``lsyd.optimise``'s rewrites, PyTorch eager (the peer), and, given ``int8`` (the folder's
    ``lsyd.variants`` int8 variant), ONNX Runtime on that, each at every thread count. The first
    three are the network of the folder's weights (``export.network_from_model``), and are
    checked to relight alike before they are timed; the int8 variant is checked to be made from
    the folder (``variants.check_made_from``). Each is fed a real face (``portrait_frame``).

    The machine is shared, so the configurations are interleaved: each round times ``frames``
    frames of every one, in an order rotated from round to round, and each reports the median,
    min and max of its rounds, in wall time and in the process's CPU time (all threads; less
    disturbed than wall time by other processes on the cores). The machine and its load
    average before and after are recorded with them."""
    net = export.network_from_model(folder)
    m = contract.read(folder / "model.json")
    r = m["resolution"]
    image, source, target = (torch.from_numpy(x) for x in portrait_frame(r))
    ref = export.reference_run(net, image, source, target)
    specs = contract.stage_specs(r, tuple(m["widths"]))
    load_before = os.getloadavg()
    folders = {ORT: folder}
    if int8 is not None:
        variants.check_made_from(folder, int8)
        folders[ORT_INT8] = int8
    with tempfile.TemporaryDirectory() as tmp:
        plain = Path(tmp)
        export.write_stages(net, specs, plain, ref, rewrite=False)
        folders[ORT_PLAIN] = plain
        for f in (folder, plain):
            export.parity(f, specs, ref)
        runs = {}
        for t in threads:
            for name, f in folders.items():
                runs[name, t] = _ort_frames(contract.StageChain(f, t), ref)
            runs[PEER, t] = _torch_frames(net, t, image, source, target)
        times: dict[tuple, list[float]] = {k: [] for k in runs}
        cpu: dict[tuple, list[float]] = {k: [] for k in runs}
        keys = list(runs)
        for i in range(rounds):
            for k in keys[i % len(keys) :] + keys[: i % len(keys)]:
                runs[k](3)  # settles the other configuration's threads and caches
                wall, used = runs[k](frames)
                times[k].append(1e3 * wall / frames)
                cpu[k].append(1e3 * used / frames)
    out: dict = {
        "machine": hardware(torch.device("cpu")),
        "rounds": rounds,
        "frames_a_round": frames,
        "load_average": [load_before[0], os.getloadavg()[0]],
    }
    for (name, t), ms in times.items():
        c = cpu[name, t]
        out.setdefault(name, {})[str(t)] = {
            "median": float(np.median(ms)),
            "min": min(ms),
            "max": max(ms),
            "cpu": {"median": float(np.median(c)), "min": min(c), "max": max(c)},
        }
    out["peer_ratio"] = {str(t): out[PEER][str(t)]["median"] / out[ORT][str(t)]["median"] for t in threads}
    if int8 is not None:
        out["peer_ratio_int8"] = {
            str(t): out[PEER][str(t)]["median"] / out[ORT_INT8][str(t)]["median"] for t in threads
        }
    return out


# The configurations ``network_timings`` times.
ORT = "onnxruntime"
ORT_INT8 = "onnxruntime, int8"
ORT_PLAIN = "onnxruntime, not rewritten"
PEER = "pytorch"


def _ort_frames(chain: contract.StageChain, ref: dict[str, np.ndarray]):
    """A timer of ``n`` frames through the stage chain."""
    target_code = chain.light_code(ref["target_light"])

    def run(n: int) -> tuple[float, float]:
        t, c = time.perf_counter(), time.process_time()
        for _ in range(n):
            chain.relight(ref["image"], ref["light"], target_code)
        return time.perf_counter() - t, time.process_time() - c

    return run


def _torch_frames(net: model.LcfnNet, threads: int, image: torch.Tensor, source: torch.Tensor, target: torch.Tensor):
    """A timer of ``n`` frames of the same stages in PyTorch eager with ``threads`` threads."""
    with torch.inference_mode():
        target_code = net.light_encoder(target)

    def run(n: int) -> tuple[float, float]:
        torch.set_num_threads(threads)
        with torch.inference_mode():
            t, c = time.perf_counter(), time.process_time()
            for _ in range(n):
                stem, feats = net.encode(image)
                net.decode(stem, net.delit(feats, net.light_encoder(source)), target_code).clamp(0.0, 1.0)
            return time.perf_counter() - t, time.process_time() - c

    return run


def network_table(timings: dict) -> str:
    """``network_timings`` as two tables, wall time and CPU time: medians with min-max,
    milliseconds a frame, and the peer's time over ONNX Runtime's."""

    def cell(x: dict) -> str:
        return f"{x['median']:.2f} ({x['min']:.2f}-{x['max']:.2f})"

    heads = {
        ORT: "ONNX Runtime",
        ORT_INT8: "ONNX Runtime, int8",
        ORT_PLAIN: "ONNX Runtime, not rewritten",
        PEER: "PyTorch eager (peer)",
    }
    names = [n for n in heads if n in timings]
    against = [n for n in (ORT, ORT_INT8) if n in timings]
    rows = []
    for what, pick in (("wall", lambda x: x), ("CPU", lambda x: x["cpu"])):
        rows += [
            f"| threads ({what} ms) | "
            + " | ".join(heads[n] for n in names)
            + "".join(f" | peer / {heads[n]}" for n in against)
            + " |",
            "|---" * (1 + len(names) + len(against)) + "|",
        ]
        for t in timings["peer_ratio"]:
            cells = [cell(pick(timings[n][t])) for n in names]
            cells += [f"{pick(timings[PEER][t])['median'] / pick(timings[n][t])['median']:.2f}x" for n in against]
            rows.append(f"| {t} | " + " | ".join(cells) + " |")
        rows.append("")
    load = timings["load_average"]
    rows.append(
        f"Milliseconds a frame, median (min-max) of {timings['rounds']} interleaved rounds of "
        f"{timings['frames_a_round']} frames each, on {timings['machine']}, shared: one-minute load average "
        f"{load[0]:.2f} before, {load[1]:.2f} after. CPU time is the process's, all its threads."
    )
    return "\n".join(rows) + "\n"


def stage_timings(folders: dict[str, Path], threads: int = 1, rounds: int = 8, frames: int = 20) -> dict:
    """CPU milliseconds a run of each stage of each model folder (say fp32 and its int8 variant),
    interleaved round by round, median (min-max): which stages a variant makes cheaper. Each
    stage is fed what it gets when a random frame is relit (``StageChain.stage_inputs``)."""
    rng = np.random.default_rng(0)
    chains = {k: contract.StageChain(f, threads) for k, f in folders.items()}
    r = next(iter(chains.values())).resolution
    image = rng.random((1, 3, r, r), dtype=np.float32)
    light = rng.random((1, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS), dtype=np.float32)
    feeds = {k: c.stage_inputs(image, light, light) for k, c in chains.items()}
    cpu: dict[str, dict[str, list[float]]] = {s: {k: [] for k in chains} for s in contract.STAGES}
    for _ in range(rounds):
        for k, c in chains.items():
            for stage, feed in feeds[k].items():
                session = c.sessions[stage]
                for _ in range(3):
                    session.run(None, feed)
                t = time.process_time()
                for _ in range(frames):
                    session.run(None, feed)
                cpu[stage][k].append(1e3 * (time.process_time() - t) / frames)
    return {
        s: {k: {"median": float(np.median(v)), "min": min(v), "max": max(v)} for k, v in d.items()}
        for s, d in cpu.items()
    }


def network_after_traffic(
    folder: Path, sizes_mb: tuple[int, ...] = (0, 1, 4, 12, 32, 64), threads: int = 2, rounds: int = 10
) -> dict[int, dict]:
    """Wall milliseconds of the network (``StageChain``, known source) on frames after which
    the calling thread copies ``sizes_mb`` megabytes, as the element's conversion, crop and
    paste of a bigger video frame stream through memory between two network runs: whether
    the network's time depends on the cache it finds. Sizes interleaved round by round; each
    round's median of 15 frames, then median (min-max) over rounds."""
    chain = contract.StageChain(folder, threads)
    rng = np.random.default_rng(0)
    r = chain.resolution
    image = rng.random((1, 3, r, r), dtype=np.float32)
    light = rng.random((1, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS), dtype=np.float32)
    code = chain.light_code(light)
    src = np.ones(max(sizes_mb) << 20, np.uint8)
    dst = np.empty_like(src)
    out: dict[int, list[float]] = {s: [] for s in sizes_mb}
    for i in range(rounds):
        k = i % len(sizes_mb)
        for size in sizes_mb[k:] + sizes_mb[:k]:
            ms = []
            for frame in range(18):
                np.copyto(dst[: size << 20], src[: size << 20])
                t = time.perf_counter()
                chain.relight(image, light, code)
                if frame >= 3:
                    ms.append(1e3 * (time.perf_counter() - t))
            out[size].append(float(np.median(ms)))
    return {s: {"median": float(np.median(v)), "min": min(v), "max": max(v)} for s, v in out.items()}


def sustained_gflops(threads: int) -> float:
    """GFLOP/s of ONNX Runtime on a stack of 3x3 convolutions like the network's (32 channels, 64x64)."""
    c, hw, depth = 32, 64, 8
    rng = np.random.default_rng(0)
    nodes, inits = [], []
    prev = "x"
    for k in range(depth):
        w = helper.make_tensor(
            f"w{k}",
            TensorProto.FLOAT,
            [c, c, 3, 3],
            rng.standard_normal((c, c, 3, 3)).astype(np.float32).ravel() * 0.05,
        )
        inits.append(w)
        nodes.append(helper.make_node("Conv", [prev, f"w{k}"], [f"y{k}"], pads=[1, 1, 1, 1]))
        prev = f"y{k}"
    graph = helper.make_graph(
        nodes,
        "convs",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, c, hw, hw])],
        [helper.make_tensor_value_info(prev, TensorProto.FLOAT, [1, c, hw, hw])],
        inits,
    )
    # ir_version pinned: onnx 1.23 writes IR 14 by default, newer than ONNX Runtime 1.31 reads.
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    s = ort.InferenceSession(m.SerializeToString(), opts, providers=["CPUExecutionProvider"])
    x = rng.random((1, c, hw, hw), dtype=np.float32)
    for _ in range(10):
        s.run(None, {"x": x})
    n = 200
    t = time.perf_counter()
    for _ in range(n):
        s.run(None, {"x": x})
    flops = 2 * c * c * 9 * hw * hw * depth * n
    return flops / (time.perf_counter() - t) / 1e9


def model_flops(folder: Path) -> float:
    """GFLOP of one frame as the engine runs it (``model.frame_flops``)."""
    m = contract.read(folder / "model.json")
    width = m["widths"][1] / model.PAPER_WIDTHS[1]
    net = model.build(model.NetConfig(resolution=m["resolution"], width=width))
    return model.frame_flops(net, m["resolution"]) / 1e9


def frames_weighted(recs: list[dict], key: str) -> float | list[float]:
    """A recording metric averaged over recordings, weighted by their frames."""
    weights = [x["frames"] for x in recs]
    values = np.array([x[key] for x in recs], dtype=np.float64)
    mean = np.average(values, axis=0, weights=weights)
    return mean.tolist() if values.ndim > 1 else float(mean)


def report(data_root: Path, out: Path) -> None:
    default = ROOT / "models" / "default"
    shipped_int8 = ROOT / "models" / "default-int8"
    # First: it checks that the shipped int8 variant is still the default's, before the long work.
    network = network_timings(default, int8=shipped_int8 if shipped_int8.exists() else None)
    element = json.loads((out / "element.json").read_text())
    sets = {name: data.Heldout.load(data_root / name) for name in ("validation", "heldout")}
    limit2 = sustained_gflops(2)
    limit1 = sustained_gflops(1)
    rows = []
    accuracy_cache: dict[str, dict] = {}
    for r in element:
        v = r["variant"]
        folder = Path(v["model"])
        key = str(folder)
        if key not in accuracy_cache:
            print(f"accuracy on the validation and held-out sets: {folder.name}", flush=True)
            accuracy_cache[key] = {name: test_set_accuracy(folder, held) for name, held in sets.items()}
        acc = accuracy_cache[key]
        recs = r["recordings"]
        frames = sum(x["frames"] for x in recs)
        rows.append(
            {
                "name": v["name"],
                "group": v["group"],
                "model": folder.name,
                "threads": v["threads"],
                "properties": v["properties"],
                "gflop": model_flops(folder),
                "validation_rmse": acc["validation"]["rmse"],
                **{f"heldout_{k}": val for k, val in acc["heldout"].items()},
                "recording_rmse": frames_weighted(recs, "rmse_region"),
                "adjacent_rmse": frames_weighted(recs, "adjacent_rmse"),
                "adjacent_over": frames_weighted(recs, "adjacent_over"),
                "change_rmse": frames_weighted(recs, "change_rmse"),
                "fps": frames / sum(x["frames"] / x["fps"] for x in recs),
                "cpu_s_per_frame": r["cpu_seconds_per_frame"],
                "peak_rss_mb": r["peak_rss_mb"],
                "latency": r["latency"],
                "recordings": recs,
            }
        )
    gflop = model_flops(default)
    cuda_rows = [r for r in rows if r["group"] == "provider"]
    summary = {
        "sustained_gflops": {"1": limit1, "2": limit2},
        "network": network,
        "default_gflop": gflop,
        "limit_fps_2_threads": limit2 / gflop,
        "cuda": (
            "measured, see the provider rows"
            if cuda_rows
            else "not measured: this machine has no GPU (no /dev/nvidia0), so the element's benchmark ran no "
            "CUDA variant"
        ),
    }
    (out / "results.json").write_text(json.dumps({"rows": rows, "summary": summary}, indent=2) + "\n")
    (out / "table.md").write_text(table(rows, summary))
    (out / "skips.md").write_text(skip_table(rows))
    pareto(rows, out / "pareto.png")
    print(table(rows, summary))
    print(skip_table(rows))


def latency_cell(latency: list[dict], size: str) -> str:
    x = next((x for x in latency if f"{x['width']}x{x['height']}" == size), None)
    return f"{x['p50_ms']:.1f} / {x['p99_ms']:.1f}" if x else ""


def table(rows: list[dict], summary: dict) -> str:
    t = metrics.TEMPORAL_THRESHOLDS
    out = [
        "| variant | comparison | GFLOP | validation RMSE | held-out RMSE | MS-SSIM | FLIP | recordings RMSE "
        f"| adjacent RMSE | >{t[0]:g} / >{t[1]:g} / >{t[2]:g} | change RMSE | fps | CPU s/frame | peak MB "
        "| p50/p99 ms 720p | p50/p99 ms 1080p |",
        "|---" * 16 + "|",
    ]
    for r in rows:
        rates = " / ".join(f"{100 * x:.0f}%" for x in r["adjacent_over"])
        out.append(
            f"| {r['name']} | {r['group']} | {r['gflop']:.3f} | {r['validation_rmse']:.2f} | "
            f"{r['heldout_rmse']:.2f} | {r['heldout_ms_ssim']:.4f} | {r['heldout_flip']:.4f} | "
            f"{r['recording_rmse']:.2f} | {r['adjacent_rmse']:.2f} | {rates} | {r['change_rmse']:.2f} | "
            f"{r['fps']:.1f} | {r['cpu_s_per_frame']:.3f} | {r['peak_rss_mb']:.0f} | "
            f"{latency_cell(r['latency'], '1280x720')} | {latency_cell(r['latency'], '1920x1080')} |"
        )
    s = summary
    out += [
        "",
        "Network alone, the default model in ONNX Runtime as the element runs it, its shipped int8 variant "
        "(`models/default-int8`, where there is one), the same network without `lsyd.optimise`'s rewrites, "
        "and in PyTorch eager (the peer):",
        "",
        network_table(s["network"]),
        f"- Limit: {s['default_gflop']:.3f} GFLOP a frame at this machine's sustained "
        f"{s['sustained_gflops']['2']:.0f} GFLOP/s (ONNX Runtime, 2 threads, 3x3 convolutions of 32 channels) "
        f"is {s['limit_fps_2_threads']:.0f} fps for the network.",
        f"- CUDA: {s['cuda']}.",
        "",
        "Per frame through the element, one frame in flight (every frame runs the network), I420 input; "
        "milliseconds from the element's statistics:",
        "",
        "| variant | input | p50 ms | p99 ms | fps | element | network | outside the network "
        "| crop and conversion | paste | averaging and smoothing | monitor frames |",
        "|---" * 12 + "|",
    ]
    for r in rows:
        for x in r["latency"]:
            outside = x["processing_ms"] - x["network_ms"]
            out.append(
                f"| {r['name']} | {x['width']}x{x['height']} | {x['p50_ms']:.1f} | {x['p99_ms']:.1f} | "
                f"{x['fps']:.1f} | {x['processing_ms']:.2f} | {x['network_ms']:.2f} | {outside:.2f} "
                f"({100 * outside / x['processing_ms']:.0f}%) | {x['crop_ms']:.2f} | {x['paste_ms']:.2f} | "
                f"{x['smoothing_ms']:.3f} | {x['monitor_light_ms']:.2f} |"
            )
    return "\n".join(out) + "\n"


def skip_table(rows: list[dict]) -> str:
    out = [
        "| setting | recording | fps | RMSE face region | change RMSE | frames skipped |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r["group"] != "skip":
            continue
        for x in r["recordings"]:
            st = x["stats"]
            skipped = sum(st.get(k, 0) for k in SKIP_COUNTS)
            out.append(
                f"| {r['name']} | {x['recording']} | {x['fps']:.1f} | {x['rmse_region']:.2f} | "
                f"{x['change_rmse']:.2f} | {skipped}/{st.get('frames', 0)} |"
            )
    return "\n".join(out) + "\n"


def element_fps(row: dict) -> float:
    """Frames a second of the element's own time (its ``frame-seconds``) over the recordings: the
    run's wall-clock fps also counts the harness reading and scoring each frame."""
    recs = row["recordings"]
    return sum(x["frames"] for x in recs) / sum(x["stats"]["frame-seconds"] for x in recs)


def pareto(rows: list[dict], path: Path) -> None:
    """The element's frames per second against validation error: the set the default was chosen on."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = [dict(r, fps=element_fps(r)) for r in rows if r["group"] in ("model", "precision", "threads")]
    fig, ax = plt.subplots(figsize=(8, 5.5))
    front = []
    for r in sorted(pts, key=lambda r: -r["fps"]):
        # Below the table's 0.01 a lower error is rounding (fp16 against fp32), not accuracy.
        if not front or r["validation_rmse"] < front[-1]["validation_rmse"] - 0.005:
            front.append(r)
    for r in pts:
        on = r in front
        ax.scatter(r["fps"], r["validation_rmse"], s=70 if on else 40, c="#2a6" if on else "#999", zorder=3)
        ax.annotate(r["name"], (r["fps"], r["validation_rmse"]), textcoords="offset points", xytext=(5, 4), fontsize=8)
    ax.plot(
        [r["fps"] for r in front],
        [r["validation_rmse"] for r in front],
        c="#2a6",
        lw=1,
        zorder=2,
        label="Pareto front",
    )
    ax.axvline(30, c="#c44", ls="--", lw=1, label="30 fps (real time)")
    ax.set_xlabel("frames per second of the element's own time (480x360 recordings, 2-core CPU)")
    ax.set_ylabel("validation RMSE (0-255), lower is better")
    ax.set_title("Run time against error")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "stage",
        choices=["export", "report", "network", "stages", "traffic", "skips"],
        help="network: the network alone against PyTorch; stages: CPU time of each stage of --model, "
        "--int8 and --against; traffic: the network's time after memory traffic between frames; skips: only the "
        "skip table, from the element's run alone (`--group skip`)",
    )
    p.add_argument("--data", type=Path, default=ROOT / "data")
    p.add_argument("--runs", type=Path, default=ROOT / "runs")
    p.add_argument("--out", type=Path, default=ROOT / "results" / "benchmark")
    p.add_argument("--model", type=Path, default=ROOT / "models" / "default", help="the model the network stage times")
    p.add_argument("--int8", type=Path, help="network: also time this int8 variant of --model (`lsyd.variants`)")
    p.add_argument(
        "--against",
        type=Path,
        nargs="+",
        default=[],
        help="stages: also time these folders of the same network (say --model and its int8 variant before a "
        "rewrite), interleaved",
    )
    a = p.parse_args()
    if a.stage == "export":
        export_all(a.data, a.runs)
    elif a.stage == "report":
        report(a.data, a.out)
    elif a.stage == "stages":
        folders = {"fp32": a.model, "int8": a.int8, **{str(f): f for f in a.against}}
        folders = {k: f for k, f in folders.items() if f is not None}
        by_stage = stage_timings(folders)
        for stage, by in by_stage.items():
            cells = ", ".join(f"{k} {v['median']:.3f} ({v['min']:.3f}-{v['max']:.3f})" for k, v in by.items())
            print(f"{stage}: {cells} CPU ms a run, 1 thread")
        # What relighting with the source light known runs: every stage but the light decoder.
        known = [s for s in by_stage if s != "light_decoder"]
        sums = ", ".join(f"{k} {sum(by_stage[s][k]['median'] for s in known):.3f}" for k in folders)
        print(f"the network, source known (sum of medians): {sums} CPU ms, 1 thread")
    elif a.stage == "traffic":
        load = os.getloadavg()[0]
        for size, v in network_after_traffic(a.model).items():
            print(f"{size} MB copied before each frame: {v['median']:.2f} ({v['min']:.2f}-{v['max']:.2f}) ms")
        print(f"one-minute load average {load:.2f} before, {os.getloadavg()[0]:.2f} after")
    elif a.stage == "skips":
        element = json.loads((a.out / "element.json").read_text())
        rows = [{**r["variant"], "recordings": r["recordings"]} for r in element]
        (a.out / "skips.md").write_text(skip_table(rows))
        print(skip_table(rows))
    else:
        timings = network_timings(a.model, int8=a.int8)
        a.out.mkdir(parents=True, exist_ok=True)
        (a.out / "network.json").write_text(json.dumps(timings, indent=2) + "\n")
        (a.out / "network.md").write_text(network_table(timings))
        print(network_table(timings))


if __name__ == "__main__":
    main()
