//! `--stages`: where the element's time goes, every frame through the
//! network, at 480p, 720p, 1080p and 2160p in I420, NV12 and BGRx, in
//! interleaved rounds, beside published anchors.

use std::path::Path;

use lsydrelight_testkit::checkout;

use crate::full_run::Variant;
use crate::latency::{LatencyResult, latency};

/// Published per-frame figures of NVIDIA Maxine's video relighting at 720p on
/// data-centre GPUs (from the project's issue 11): anchors, not measured here.
const MAXINE_720P_MS: [(&str, f64); 3] = [("T4", 54.0), ("A40", 17.1), ("L40", 8.0)];

/// Where the time goes at each size and format, every frame through the network,
/// in `rounds` interleaved rounds; a markdown table of medians and min-max.
pub(crate) fn stages(
    rounds: usize,
    only: &[String],
    threads: u32,
    model: &Path,
) -> Result<String, String> {
    let every_frame = Variant {
        name: "every frame".into(),
        group: "stages".into(),
        model: model.to_path_buf(),
        threads,
        properties: vec![("reuse-interval".into(), "1".into())],
        recordings: vec![],
        latency_sizes: vec![],
    };
    let cases: Vec<((u32, u32), &str)> = [(854, 480), (1280, 720), (1920, 1080), (3840, 2160)]
        .into_iter()
        .flat_map(|size| ["I420", "NV12", "BGRx"].map(|format| (size, format)))
        .filter(|&((w, h), format)| {
            only.is_empty() || only.iter().any(|o| *o == format!("{w}x{h}/{format}"))
        })
        .collect();
    let mut runs: Vec<Vec<LatencyResult>> = cases.iter().map(|_| Vec::new()).collect();
    for round in 0..rounds {
        for (&((w, h), format), results) in cases.iter().zip(&mut runs) {
            eprintln!("stages: round {} {w}x{h} {format}", round + 1);
            results.push(latency(&every_frame, w, h, format, 60)?);
        }
    }
    let spread = |xs: Vec<f64>| {
        let mut xs = xs;
        xs.sort_by(f64::total_cmp);
        let median = xs[xs.len() / 2];
        format!("{median:.2} ({:.2}-{:.2})", xs[0], xs[xs.len() - 1])
    };
    let anchors: Vec<String> = MAXINE_720P_MS
        .iter()
        .map(|(gpu, ms)| format!("{ms} ms on {gpu}"))
        .collect();
    let mut out = vec![
        format!(
            "Per frame, every frame through the network (`{}`), one frame in flight, network on \
             {threads} thread(s); median (min-max) of {rounds} interleaved rounds of 60 frames (10 more to warm up) \
             on this 2-core CPU. Published anchor, not measured here: NVIDIA Maxine video \
             relighting at 720p, {}.",
            model.strip_prefix(checkout()).unwrap_or(model).display(),
            anchors.join(", ")
        ),
        String::new(),
        "| input | format | p50 ms | p99 ms | element ms | network | crop | paste | rest | fps |"
            .into(),
        "|---|---|---|---|---|---|---|---|---|---|".into(),
    ];
    let mut rest = vec![
        String::new(),
        "The rest, by stage (same runs, ms a frame): following the face (tracker, and \
         the detector every 5th frame), building the lighting change, the temporal \
         smoothing, the policy's deciding, the element's setup (lock, target, mapping \
         the frame) and finish; outside: the frame's time in the element beyond these \
         (its monitor frame's light, `monitor_src`, QoS)."
            .into(),
        String::new(),
        "| input | format | rest | follow | change | smoothing | decide | setup | finish | outside |"
            .into(),
        "|---|---|---|---|---|---|---|---|---|---|".into(),
    ];
    for (((w, h), format), results) in cases.iter().zip(&runs) {
        let col = |f: &dyn Fn(&LatencyResult) -> f64| spread(results.iter().map(f).collect());
        out.push(format!(
            "| {w}x{h} | {format} | {} | {} | {} | {} | {} | {} | {} | {} |",
            col(&|x| x.p50_ms),
            col(&|x| x.p99_ms),
            col(&|x| x.processing_ms),
            col(&|x| x.network_ms),
            col(&|x| x.crop_ms),
            col(&|x| x.paste_ms),
            col(&|x| x.processing_ms - x.network_ms - x.crop_ms - x.paste_ms),
            col(&|x| x.fps),
        ));
        rest.push(format!(
            "| {w}x{h} | {format} | {} | {} | {} | {} | {} | {} | {} | {} |",
            col(&|x| x.processing_ms - x.network_ms - x.crop_ms - x.paste_ms),
            col(&|x| x.follow_ms),
            col(&|x| x.change_ms),
            col(&|x| x.smoothing_ms),
            col(&|x| x.decide_ms),
            col(&|x| x.setup_ms),
            col(&|x| x.finish_ms),
            col(&|x| x.frame_ms - x.processing_ms),
        ));
    }
    out.extend(rest);
    Ok(out.join("\n") + "\n")
}
