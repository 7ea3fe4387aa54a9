//! Measures the monitor-match check (the paper's section 4.3) on simulator
//! recordings: how well the light predicted from the face tells the screen the
//! face really faced from another recording's screen, or from its own screen
//! shown late.
//!
//! Each recording's face video runs once through the element with its own
//! monitor stream and `monitor_src` linked; the predicted light of every face
//! frame is read back from `monitor_src`. The screen's light of every frame is
//! computed from the monitor videos as the element computes it. Then, with the
//! element's own scorer (`gstlsydrelight::monitor_match`), windows sliding every
//! half second are scored for
//!
//! - genuine pairs: the face with its own screen;
//! - delayed pairs: the face with its own screen 0.5, 1 and 2 s earlier (a replay
//!   or a synthesised face that follows the screen late);
//! - swapped pairs: the face with another recording's screen.
//!
//! and the ROC curve and its AUC are computed per window length. The check needs
//! a screen that changes: windows where the screen stayed still, or the face was
//! mostly away, get no score and are counted apart.
//!
//! ```text
//! cargo run --release --example match_check -- [--frames 300] [--dir target/recordings]
//!     [--recordings cuts,slow,call,walkaway,steady] [--out results/match_check]
//! ```
//!
//! Writes `<out>/table.md` and `<out>/results.json`; `results/match_check/plot.py`
//! draws the ROC curves from the JSON.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use deskstage::io::Y4mReader;
use gst::prelude::*;
use gst_video::prelude::*;
use gstlsydrelight::frame::Frame;
use gstlsydrelight::light::Light;
use gstlsydrelight::monitor_match::{Component, Features, MatchSettings, MatchWindow, Verdict};
use lsydrelight_testkit::{
    checkout, default_model, flags::flag, init, recording::ensure_recording,
};

/// Window lengths measured, seconds.
const WINDOWS: [f64; 4] = [1.0, 2.0, 3.0, 5.0];
/// Delays of the delayed pairs, seconds.
const DELAYS: [f64; 3] = [0.5, 1.0, 2.0];
/// Windows start every this many seconds.
const STEP: f64 = 0.5;

/// Per-frame features of one recording.
struct Series {
    name: String,
    fps: f64,
    screen: Vec<Features>,
    /// The prediction from each face frame; None where the element had none (no face).
    predicted: Vec<Option<Features>>,
}

fn screen_features(path: &Path) -> Result<Vec<Features>, String> {
    let mut reader = Y4mReader::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut out = Vec::new();
    while let Some(img) = reader.next_frame().map_err(|e| e.to_string())? {
        let light = Light::from_frame(&Frame::packed_rgb(&img.data, img.width, img.height));
        out.push(Features::of(&light));
    }
    Ok(out)
}

/// Runs the face video through the element with its monitor stream and reads the
/// predicted light of each frame from `monitor_src`.
fn predicted_features(
    dir: &Path,
    model: &Path,
    frames: usize,
    fps: f64,
) -> Result<Vec<Option<Features>>, String> {
    init();
    let play = |file: &str| {
        format!(
            "filesrc location=\"{}\" ! y4mdec ! capssetter caps=\"video/x-raw,colorimetry=bt601,chroma-site=jpeg\"",
            dir.join(file).display()
        )
    };
    let pipeline = gst::parse::launch(&format!(
        "lsydrelight name=r {face} ! queue max-size-buffers=4 ! r.sink \
         {monitor} ! queue max-size-buffers=4 ! r.monitor_sink \
         r.src ! queue ! fakesink sync=false \
         r.monitor_src ! queue ! appsink name=predicted sync=false",
        face = play("face.y4m"),
        monitor = play("monitor.y4m"),
    ))
    .map_err(|e| e.to_string())?
    .downcast::<gst::Pipeline>()
    .map_err(|_| "not a pipeline")?;
    let r = pipeline.by_name("r").ok_or("no element r")?;
    r.set_property(
        "model-location",
        model.to_str().ok_or("model path is not UTF-8")?,
    );
    r.set_property(
        "target-location",
        dir.join("target-studio.png")
            .to_str()
            .ok_or("path is not UTF-8")?,
    );
    let sink = pipeline
        .by_name("predicted")
        .ok_or("no appsink")?
        .downcast::<gst_app::AppSink>()
        .map_err(|_| "not an appsink")?;
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| format!("cannot play: {e}"))?;
    let mut predicted = vec![None; frames];
    let result = loop {
        let Some(sample) = sink.try_pull_sample(gst::ClockTime::from_seconds(120)) else {
            break if sink.is_eos() {
                Ok(())
            } else {
                Err("no predicted frame within 120 s".to_string())
            };
        };
        let (Some(buffer), Some(caps)) = (sample.buffer(), sample.caps()) else {
            break Err("a sample without buffer or caps".into());
        };
        let info = gst_video::VideoInfo::from_caps(caps).map_err(|e| e.to_string())?;
        let frame = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer, &info)
            .map_err(|e| e.to_string())?;
        let (w, h) = (info.width() as usize, info.height() as usize);
        let stride = frame.plane_stride()[0] as usize;
        let data = frame.plane_data(0).map_err(|e| e.to_string())?;
        let rgb: Vec<u8> = (0..h)
            .flat_map(|y| &data[y * stride..y * stride + 3 * w])
            .copied()
            .collect();
        let index = buffer
            .pts()
            .map(|t| (t.seconds_f64() * fps).round() as usize)
            .ok_or("a predicted frame without a timestamp")?;
        if let Some(slot) = predicted.get_mut(index) {
            *slot = Some(Features::of(&Light::from_frame(&Frame::packed_rgb(
                &rgb, w, h,
            ))));
        }
    };
    let error = pipeline
        .bus()
        .and_then(|b| b.pop_filtered(&[gst::MessageType::Error]));
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    if let Some(m) = error
        && let gst::MessageView::Error(e) = m.view()
    {
        return Err(format!("pipeline error: {} ({:?})", e.error(), e.debug()));
    }
    result?;
    Ok(predicted)
}

#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
enum Kind {
    Genuine,
    Delayed,
    Swapped,
}

/// Scored windows of one trial kind, and the windows that could not be scored.
#[derive(Default)]
struct Scores {
    scores: Vec<f64>,
    components: BTreeMap<&'static str, Vec<f64>>,
    still: usize,
    too_few: usize,
}

/// Scores windows of `window` seconds sliding over the face of `face` paired with
/// the screen of `screen` shown `delay` seconds before it.
fn score_pair(
    face: &Series,
    screen: &Series,
    delay: f64,
    window: f64,
    settings: &MatchSettings,
    out: &mut Scores,
) {
    let shift = (delay * face.fps).round() as usize;
    let frames = face.predicted.len().min(screen.screen.len() + shift);
    let per_window = (window * face.fps).round() as usize;
    let step = (STEP * face.fps).round() as usize;
    let mut end = shift + per_window;
    while end <= frames {
        let mut w = MatchWindow::default();
        for i in end - per_window..end {
            if let Some(p) = face.predicted[i] {
                w.push_features(i as f64 / face.fps, screen.screen[i - shift], p, window);
            }
        }
        let s = w.score(settings, face.fps);
        match (s.verdict, s.score) {
            (Verdict::TooFewFrames, _) => out.too_few += 1,
            (_, None) => out.still += 1,
            (_, Some(score)) => {
                out.scores.push(score);
                for (c, r) in s.components {
                    // A component that does not count scores as no agreement.
                    out.components
                        .entry(c.name())
                        .or_default()
                        .push(r.unwrap_or(0.0));
                }
            }
        }
        end += step;
    }
}

/// Area under the ROC curve: the chance a genuine window scores above an impostor one.
fn auc(positive: &[f64], negative: &[f64]) -> f64 {
    let mut wins = 0.0;
    for p in positive {
        for n in negative {
            wins += if p > n {
                1.0
            } else if p == n {
                0.5
            } else {
                0.0
            };
        }
    }
    wins / (positive.len() * negative.len()).max(1) as f64
}

/// The ROC curve as (false-positive rate, true-positive rate) per threshold, high to low.
fn roc(positive: &[f64], negative: &[f64]) -> Vec<(f64, f64, f64)> {
    let mut thresholds: Vec<f64> = positive.iter().chain(negative).copied().collect();
    thresholds.sort_by(|a, b| b.total_cmp(a));
    thresholds.dedup();
    let rate =
        |v: &[f64], t: f64| v.iter().filter(|x| **x >= t).count() as f64 / v.len().max(1) as f64;
    let mut curve = vec![(f64::INFINITY, 0.0, 0.0)];
    curve.extend(
        thresholds
            .iter()
            .map(|&t| (t, rate(negative, t), rate(positive, t))),
    );
    curve
}

fn main() -> Result<(), String> {
    let frames: usize = flag("--frames")
        .map(|f| f.parse().map_err(|_| "bad --frames"))
        .transpose()?
        .unwrap_or(300);
    let dir = flag("--dir")
        .map(PathBuf::from)
        .unwrap_or_else(|| checkout().join("target/recordings"));
    let out = flag("--out")
        .map(PathBuf::from)
        .unwrap_or_else(|| checkout().join("results/match_check"));
    let model = flag("--model")
        .map(PathBuf::from)
        .unwrap_or_else(default_model);
    let names = flag("--recordings").unwrap_or_else(|| "cuts,slow,call,walkaway,steady".into());
    let settings = MatchSettings::default();

    let mut series = Vec::new();
    for name in names.split(',') {
        let rec = dir.join(format!("{name}-{frames}"));
        ensure_recording(&rec, name, frames)?;
        let fps = Y4mReader::open(&rec.join("face.y4m"))
            .map_err(|e| e.to_string())?
            .fps as f64;
        let screen = screen_features(&rec.join("monitor.y4m"))?;
        let started = std::time::Instant::now();
        let predicted = predicted_features(&rec, &model, frames, fps)?;
        eprintln!(
            "{name}: {} of {frames} frames with a prediction ({:.1} s)",
            predicted.iter().flatten().count(),
            started.elapsed().as_secs_f64()
        );
        series.push(Series {
            name: name.to_string(),
            fps,
            screen,
            predicted,
        });
    }
    if let Some(path) = flag("--dump") {
        // The per-frame features, for analysis outside this program.
        let f = |x: &Features| [x.luminance, x.colour, x.spatial];
        let dump: serde_json::Map<String, serde_json::Value> = series
            .iter()
            .map(|s| {
                let screen: Vec<_> = s.screen.iter().map(f).collect();
                let predicted: Vec<_> = s.predicted.iter().map(|p| p.as_ref().map(f)).collect();
                (
                    s.name.clone(),
                    serde_json::json!({ "fps": s.fps, "screen": screen, "predicted": predicted }),
                )
            })
            .collect();
        std::fs::write(&path, serde_json::to_string(&dump).unwrap()).map_err(|e| e.to_string())?;
    }

    let mut table = String::from(
        "| window | AUC | AUC against delayed | AUC against swapped | AUC luminance | AUC colour | AUC spatial | genuine windows | delayed | swapped | TPR at threshold | FPR at threshold | unscored: still screen / face away |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut json = serde_json::Map::new();
    for window in WINDOWS {
        let mut by_kind: BTreeMap<Kind, Scores> = BTreeMap::new();
        for face in &series {
            score_pair(
                face,
                face,
                0.0,
                window,
                &settings,
                by_kind.entry(Kind::Genuine).or_default(),
            );
            for delay in DELAYS {
                score_pair(
                    face,
                    face,
                    delay,
                    window,
                    &settings,
                    by_kind.entry(Kind::Delayed).or_default(),
                );
            }
            for screen in series.iter().filter(|s| s.name != face.name) {
                score_pair(
                    face,
                    screen,
                    0.0,
                    window,
                    &settings,
                    by_kind.entry(Kind::Swapped).or_default(),
                );
            }
        }
        let genuine = &by_kind[&Kind::Genuine];
        let (delayed, swapped) = (&by_kind[&Kind::Delayed], &by_kind[&Kind::Swapped]);
        let impostor: Vec<f64> = delayed
            .scores
            .iter()
            .chain(&swapped.scores)
            .copied()
            .collect();
        let component_auc = |c: Component| {
            let imp: Vec<f64> = delayed.components[c.name()]
                .iter()
                .chain(&swapped.components[c.name()])
                .copied()
                .collect();
            auc(&genuine.components[c.name()], &imp)
        };
        let rate = |v: &[f64]| {
            v.iter().filter(|s| **s >= settings.threshold).count() as f64 / v.len().max(1) as f64
        };
        let unscored = |s: &Scores| format!("{}/{}", s.still, s.too_few);
        let all_auc = auc(&genuine.scores, &impostor);
        table += &format!(
            "| {window} s | {all_auc:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {:.3} | {:.3} | genuine {}, delayed {}, swapped {} |\n",
            auc(&genuine.scores, &delayed.scores),
            auc(&genuine.scores, &swapped.scores),
            component_auc(Component::Luminance),
            component_auc(Component::Colour),
            component_auc(Component::Spatial),
            genuine.scores.len(),
            delayed.scores.len(),
            swapped.scores.len(),
            rate(&genuine.scores),
            rate(&impostor),
            unscored(genuine),
            unscored(delayed),
            unscored(swapped),
        );
        json.insert(
            format!("{window}"),
            serde_json::json!({
                "auc": all_auc,
                "auc_delayed": auc(&genuine.scores, &delayed.scores),
                "auc_swapped": auc(&genuine.scores, &swapped.scores),
                "roc": roc(&genuine.scores, &impostor).iter().skip(1).map(|(t, f, p)| [*t, *f, *p]).collect::<Vec<_>>(),
                "genuine": genuine.scores,
                "delayed": delayed.scores,
                "swapped": swapped.scores,
            }),
        );
    }
    let command = format!(
        "cargo run --release --example match_check -- --frames {frames} --recordings {names}"
    );
    let text = format!(
        "# Monitor-match check on the simulator\n\nRecordings {names} ({frames} frames each); windows every {STEP} s; delays {DELAYS:?} s; threshold {}.\n\n{table}\nMade by `{command}`.\n",
        settings.threshold
    );
    print!("{text}");
    std::fs::create_dir_all(&out).map_err(|e| e.to_string())?;
    std::fs::write(out.join("table.md"), text).map_err(|e| e.to_string())?;
    let json =
        serde_json::json!({ "command": command, "threshold": settings.threshold, "windows": json });
    std::fs::write(
        out.join("results.json"),
        serde_json::to_string(&json).unwrap() + "\n",
    )
    .map_err(|e| e.to_string())?;
    Ok(())
}
