//! Measures the monitor-match check (the paper's section 4.3) on simulator
//! recordings: how well the light predicted from the face tells the screen the
//! face really faced from another recording's screen, or from its own screen
//! shown late.
//!
//! Every pairing of a face video with a monitor stream runs through the element,
//! with `monitor_src` linked and `match-check` on:
//!
//! - genuine: the face with its own monitor stream;
//! - delayed: the face with its own monitor stream 0.5, 1 and 2 s late
//!   (`monitor-offset`: each face frame is paired with the screen that long
//!   before it, as a replayed or synthesised face that follows the screen late);
//! - swapped: the face with another recording's monitor stream.
//!
//! The predicted light of every face frame is read back from `monitor_src`, and
//! the screen's light of every frame is computed from the monitor video as the
//! element computes it. With the element's own scorer
//! (`gstlsydrelight::monitor_match`), windows sliding every half second are scored
//! and the ROC curve and its AUC computed per window length. The element's own
//! `lsydrelight-monitor-match` messages (5 s window, one a second) are scored too,
//! as a check that the element reports what this program computes. The check
//! needs a screen that changes: windows where the screen stayed still, or the
//! face was mostly away, get no score and are counted apart.
//!
//! ```text
//! cargo run --release --example match_check -- [--frames 300] [--dir target/recordings]
//!     [--recordings cuts,slow,call,walkaway,steady] [--out results/match_check] [--model DIR]
//!     [--prediction-only] [--set colour-tracking=false ...]
//! ```
//!
//! Writes `<out>/table.md` and `<out>/results.json`; `results/match_check/plot.py`
//! draws the ROC curves from the JSON. Beside them, `<out>/prediction.md`: how
//! closely the light predicted from each face follows its own screen (the
//! correlation over the frames of the screen's luminance, linear, and of its
//! colour, the features the check reads); `--prediction-only` runs the genuine
//! pairings alone for it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use clap::Parser;
use deskstage::io::Y4mReader;
use gst::prelude::*;
use gst_video::prelude::*;
use gstlsydrelight::frame::Frame;
use gstlsydrelight::light::Light;
use gstlsydrelight::monitor_match::{
    Component, Features, MatchSettings, MatchWindow, Verdict, correlation,
};
use lsydrelight_testkit::{
    checkout, default_model, init,
    recording::{ensure_recording, property_setting, set_properties},
};

/// Window lengths measured, seconds.
const WINDOWS: [f64; 4] = [1.0, 2.0, 3.0, 5.0];
/// Delays of the delayed pairs, seconds.
const DELAYS: [f64; 3] = [0.5, 1.0, 2.0];
/// Windows start every this many seconds.
const STEP: f64 = 0.5;

/// One recording: its folder, frame rate and the screen's features per frame.
struct Recorded {
    name: String,
    dir: PathBuf,
    fps: f64,
    screen: Vec<Features>,
}

/// A face paired with a monitor stream, and what the element made of it.
struct Trial {
    kind: Kind,
    face: usize,
    screen: usize,
    delay: f64,
    pairing: Pairing,
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

/// What one run of the element gave.
struct Pairing {
    /// The prediction from each face frame; None where there was none (no face).
    predicted: Vec<Option<Features>>,
    /// Scores of the element's own messages over a full window.
    element_scores: Vec<f64>,
}

/// The window of the element's own messages, seconds.
const ELEMENT_WINDOW: f64 = 5.0;

/// Runs `face_dir`'s face video through the element with `monitor_dir`'s monitor
/// stream paired `delay` seconds late, and reads the predicted light of each
/// frame from `monitor_src`.
fn run_pairing(
    face_dir: &Path,
    monitor_dir: &Path,
    delay: f64,
    model: &Path,
    properties: &[(String, String)],
    frames: usize,
    fps: f64,
) -> Result<Pairing, String> {
    init();
    let play = |path: PathBuf| {
        format!(
            "filesrc location=\"{}\" ! y4mdec ! capssetter caps=\"video/x-raw,colorimetry=bt601,chroma-site=jpeg\"",
            path.display()
        )
    };
    let pipeline = gst::parse::launch(&format!(
        "lsydrelight name=r {face} ! queue max-size-buffers=4 ! r.sink \
         {monitor} ! queue max-size-buffers=4 ! r.monitor_sink \
         r.src ! queue ! fakesink sync=false \
         r.monitor_src ! queue ! appsink name=predicted sync=false",
        face = play(face_dir.join("face.y4m")),
        monitor = play(monitor_dir.join("monitor.y4m")),
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
        face_dir
            .join("target-studio.png")
            .to_str()
            .ok_or("path is not UTF-8")?,
    );
    r.set_property("monitor-offset", (delay * 1e9).round() as i64);
    r.set_property("match-check", true);
    r.set_property("match-window", ELEMENT_WINDOW);
    set_properties(&r, properties)?;
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
    let bus = pipeline.bus().ok_or("no bus")?;
    let mut error = None;
    let mut element_scores = Vec::new();
    while let Some(m) = bus.pop() {
        match m.view() {
            gst::MessageView::Error(e) => {
                error = Some(format!("pipeline error: {} ({:?})", e.error(), e.debug()))
            }
            gst::MessageView::Element(e) => {
                if let Some(s) = e.structure()
                    && s.name() == "lsydrelight-monitor-match"
                    && let Ok(score) = s.get::<f64>("score")
                    && s.get::<u32>("frames").unwrap_or(0) as f64 >= ELEMENT_WINDOW * fps - 1.0
                {
                    element_scores.push(score);
                }
            }
            _ => {}
        }
    }
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    if let Some(e) = error {
        return Err(e);
    }
    result?;
    Ok(Pairing {
        predicted,
        element_scores,
    })
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

/// Scores windows of `window` seconds sliding over a trial's face frames, each
/// paired with the screen shown `delay` seconds before it.
fn score_trial(
    trial: &Trial,
    recordings: &[Recorded],
    window: f64,
    settings: &MatchSettings,
    out: &mut Scores,
) {
    let fps = recordings[trial.face].fps;
    let screen = &recordings[trial.screen].screen;
    let predicted = &trial.pairing.predicted;
    let shift = (trial.delay * fps).round() as usize;
    let frames = predicted.len().min(screen.len() + shift);
    let per_window = (window * fps).round() as usize;
    let step = (STEP * fps).round() as usize;
    let mut end = shift + per_window;
    while end <= frames {
        let mut w = MatchWindow::default();
        for i in end - per_window..end {
            if let Some(p) = predicted[i] {
                w.push_features(i as f64 / fps, screen[i - shift], p, window);
            }
        }
        let s = w.score(settings, fps);
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

/// Measures the monitor-match check on simulator recordings: genuine pairings
/// against swapped and delayed screens, per window length.
#[derive(Parser)]
struct Args {
    /// Frames of each recording.
    #[arg(long, default_value_t = 300)]
    frames: usize,
    /// Where the recordings are kept (default: target/recordings).
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Where the results go (default: results/match_check).
    #[arg(long)]
    out: Option<PathBuf>,
    /// The model folder (default: the element's default model).
    #[arg(long)]
    model: Option<PathBuf>,
    /// The simulator's recordings, comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "cuts,slow,call,walkaway,steady"
    )]
    recordings: Vec<String>,
    /// Only each face with its own screen: writes `<out>/prediction.md`
    /// without the check's ROC.
    #[arg(long)]
    prediction_only: bool,
    /// An element property for every pairing, as gst-launch takes it
    /// (`--set colour-tracking=false`); repeat for more.
    #[arg(long = "set", value_parser = property_setting)]
    set: Vec<(String, String)>,
}

/// How closely the light predicted from each face follows its own screen: per
/// recording, over its frames with a prediction, the correlation of the
/// predicted and the screen's luminance and colour, and their means.
fn prediction_table(trials: &[Trial], recordings: &[Recorded]) -> String {
    let mut text = String::from(
        "| recording | frames | luminance correlation | colour correlation | mean luminance, predicted / screen | mean colour, predicted / screen |\n|---|---|---|---|---|---|\n",
    );
    for trial in trials.iter().filter(|t| t.kind == Kind::Genuine) {
        let recorded = &recordings[trial.face];
        let pairs: Vec<(Features, Features)> = recorded
            .screen
            .iter()
            .zip(&trial.pairing.predicted)
            .filter_map(|(screen, predicted)| predicted.map(|p| (*screen, p)))
            .collect();
        let of = |feature: fn(&Features) -> f64| -> Vec<(f64, f64)> {
            pairs
                .iter()
                .map(|(screen, predicted)| (feature(screen), feature(predicted)))
                .collect()
        };
        // A screen (or a prediction) that does not change has nothing to
        // correlate (`steady`'s screen holds still).
        let corr = |values: &[(f64, f64)]| {
            correlation(values, 1e-4).map_or("does not vary".to_string(), |c| format!("{c:.2}"))
        };
        let means = |values: &[(f64, f64)]| {
            if values.is_empty() {
                return "no frames".to_string();
            }
            let n = values.len() as f64;
            let (s, p) = values
                .iter()
                .fold((0.0, 0.0), |(s, p), (a, b)| (s + a / n, p + b / n));
            format!("{p:.3} / {s:.3}")
        };
        let (luminance, colour) = (of(|f| f.luminance), of(|f| f.colour));
        text += &format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            recorded.name,
            pairs.len(),
            corr(&luminance),
            corr(&colour),
            means(&luminance),
            means(&colour),
        );
    }
    text
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    let frames = args.frames;
    let dir = args
        .dir
        .unwrap_or_else(|| checkout().join("target/recordings"));
    let out = args
        .out
        .unwrap_or_else(|| checkout().join("results/match_check"));
    let model = args.model.unwrap_or_else(default_model);
    let names = args.recordings;
    let settings = MatchSettings::default();

    let mut recordings = Vec::new();
    for name in &names {
        let dir = dir.join(format!("{name}-{frames}"));
        ensure_recording(&dir, name, frames)?;
        let fps = Y4mReader::open(&dir.join("face.y4m"))
            .map_err(|e| e.to_string())?
            .fps as f64;
        let screen = screen_features(&dir.join("monitor.y4m"))?;
        recordings.push(Recorded {
            name: name.to_string(),
            dir,
            fps,
            screen,
        });
    }
    let mut trials = Vec::new();
    for face in 0..recordings.len() {
        let mut pairings = vec![(Kind::Genuine, face, 0.0)];
        if !args.prediction_only {
            pairings.extend(DELAYS.map(|d| (Kind::Delayed, face, d)));
            pairings.extend(
                (0..recordings.len())
                    .filter(|s| *s != face)
                    .map(|s| (Kind::Swapped, s, 0.0)),
            );
        }
        for (kind, screen, delay) in pairings {
            let started = std::time::Instant::now();
            let (f, s) = (&recordings[face], &recordings[screen]);
            let pairing = run_pairing(&f.dir, &s.dir, delay, &model, &args.set, frames, f.fps)?;
            eprintln!(
                "face {} with screen {} {delay} s late: {} of {frames} frames with a prediction, {} element messages over a full window ({:.1} s)",
                f.name,
                s.name,
                pairing.predicted.iter().flatten().count(),
                pairing.element_scores.len(),
                started.elapsed().as_secs_f64()
            );
            trials.push(Trial {
                kind,
                face,
                screen,
                delay,
                pairing,
            });
        }
    }
    let names = names.join(",");
    let set: String = args
        .set
        .iter()
        .map(|(k, v)| format!(" --set {k}={v}"))
        .collect();
    let command = format!(
        "cargo run --release --example match_check -- --frames {frames} --recordings {names} --model {}{set}",
        model.display()
    );
    std::fs::create_dir_all(&out).map_err(|e| e.to_string())?;
    let prediction = format!(
        "# The light predicted from the face against its own screen\n\nRecordings {names} ({frames} frames each), model `{}`, its light decoder's prediction read from `monitor_src` while the face's own monitor stream plays: luminance (linear; the monitor-match check correlates its logarithm) and colour (blue less red over the sum), the features the check reads.\n\n{}\nMade by `{command} --prediction-only`.\n",
        model.display(),
        prediction_table(&trials, &recordings),
    );
    print!("{prediction}");
    std::fs::write(out.join("prediction.md"), &prediction).map_err(|e| e.to_string())?;
    if args.prediction_only {
        return Ok(());
    }
    let element_scores = |kind: Kind| -> Vec<f64> {
        trials
            .iter()
            .filter(|t| t.kind == kind)
            .flat_map(|t| t.pairing.element_scores.iter().copied())
            .collect()
    };
    let (element_genuine, mut element_impostor) =
        (element_scores(Kind::Genuine), element_scores(Kind::Delayed));
    element_impostor.extend(element_scores(Kind::Swapped));
    let element_auc = auc(&element_genuine, &element_impostor);

    let mut table = String::from(
        "| window | AUC | AUC against delayed | against 0.5 / 1 / 2 s late | AUC against swapped | AUC luminance | AUC luminance change | AUC colour | AUC spatial | genuine windows | delayed | swapped | TPR at threshold | FPR at threshold | unscored: still screen / face away |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut json = serde_json::Map::new();
    for window in WINDOWS {
        let settings = MatchSettings { window, ..settings };
        let mut by_kind: BTreeMap<Kind, Scores> = BTreeMap::new();
        let mut by_delay: BTreeMap<String, Scores> = BTreeMap::new();
        for trial in &trials {
            let scores = by_kind.entry(trial.kind).or_default();
            score_trial(trial, &recordings, window, &settings, scores);
            if trial.kind == Kind::Delayed {
                let scores = by_delay.entry(format!("{}", trial.delay)).or_default();
                score_trial(trial, &recordings, window, &settings, scores);
            }
        }
        let per_delay: Vec<String> = DELAYS
            .iter()
            .map(|d| {
                format!(
                    "{:.3}",
                    auc(
                        &by_kind[&Kind::Genuine].scores,
                        &by_delay[&format!("{d}")].scores
                    )
                )
            })
            .collect();
        let genuine = &by_kind[&Kind::Genuine];
        let (delayed, swapped) = (&by_kind[&Kind::Delayed], &by_kind[&Kind::Swapped]);
        let impostor: Vec<f64> = delayed
            .scores
            .iter()
            .chain(&swapped.scores)
            .copied()
            .collect();
        let component_auc = |c: Component| {
            let values = |s: &Scores| s.components.get(c.name()).cloned().unwrap_or_default();
            let mut impostor = values(delayed);
            impostor.extend(values(swapped));
            auc(&values(genuine), &impostor)
        };
        let rate = |v: &[f64]| {
            v.iter().filter(|s| **s >= settings.threshold).count() as f64 / v.len().max(1) as f64
        };
        let unscored = |s: &Scores| format!("{}/{}", s.still, s.too_few);
        let all_auc = auc(&genuine.scores, &impostor);
        table += &format!(
            "| {window} s | {all_auc:.3} | {:.3} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {:.3} | {:.3} | genuine {}, delayed {}, swapped {} |\n",
            auc(&genuine.scores, &delayed.scores),
            per_delay.join(" / "),
            auc(&genuine.scores, &swapped.scores),
            component_auc(Component::Luminance),
            component_auc(Component::LuminanceChange),
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
    let text = format!(
        "# Monitor-match check on the simulator\n\nRecordings {names} ({frames} frames each); windows every {STEP} s; delays {DELAYS:?} s; threshold {}.\n\n{table}\nThe element's own messages ({ELEMENT_WINDOW} s window, one a second, full windows only): AUC {element_auc:.3} over {} genuine and {} impostor messages.\n\nMade by `{command}`.\n",
        settings.threshold,
        element_genuine.len(),
        element_impostor.len(),
    );
    print!("{text}");
    std::fs::write(out.join("table.md"), text).map_err(|e| e.to_string())?;
    let json = serde_json::json!({
        "command": command,
        "threshold": settings.threshold,
        "windows": json,
        "element_messages": {
            "window": ELEMENT_WINDOW,
            "auc": element_auc,
            "genuine": element_genuine,
            "impostor": element_impostor,
        },
    });
    std::fs::write(
        out.join("results.json"),
        serde_json::to_string(&json).unwrap() + "\n",
    )
    .map_err(|e| e.to_string())?;
    Ok(())
}
