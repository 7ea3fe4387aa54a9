//! README.md's live recipes ("Live: calls and OBS"), run as the README writes
//! them, with only the devices swapped for headless stand-ins: the webcam is the
//! shipped recording pushed by a live `appsrc` at the camera's rate, the screen is
//! `videotestsrc is-live=true`, every window and virtual camera is an `appsink`
//! that syncs to the clock and drops late frames as a video sink does, and OBS's
//! `video.` is what obs-gstreamer puts in front of the pipeline. Each run must
//! account for every frame (shown, or dropped by QoS) and keep real time: almost
//! none late enough for a video sink to drop, and the lateness against the
//! pipeline clock not growing over the run. On an overloaded machine (see
//! [`overload`]) the real-time checks print what they saw instead of failing.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread;
use std::time::{Duration, Instant};

use gst::prelude::*;
use lsydrelight_testkit::{checkout, init};

/// The camera stand-in's picture size: small, so that two cores keep up with 60 fps.
const WIDTH: i32 = 320;
const HEIGHT: i32 = 240;

/// How late a frame may reach a video sink before it is dropped (what
/// `xvimagesink`, `v4l2sink` and the other video sinks default to).
const MAX_LATENESS: gst::ClockTime = gst::ClockTime::from_mseconds(20);

/// What obs-gstreamer puts in front of the user's pipeline (the appsink it reads
/// frames from, behind the `videoconvert` named `video`).
const OBS_SINK: &str = "video_appsink";
const OBS_VIDEO: &str = "videoconvert name=video ! \
    video/x-raw,format={I420,NV12,BGRA,BGRx,RGBx,RGBA,YUY2,YVYU,UYVY} ! appsink name=video_appsink";

/// How much later the frames of a run's last 10 s (a third of a shorter run) may
/// reach the sink than those of its first 10 s.
const GROWTH_MARGIN_MS: f64 = 20.0;

/// The share of frames the sinks may drop for lateness after the first WARM_UP.
const DROPPED_SHARE: f64 = 0.01;

/// The same for a 2160p camera on a 2-core machine, which is at its limit there:
/// at most 1.3% dropped in the runs measured with QoS working, 88% with it broken.
const DROPPED_SHARE_AT_LIMIT: f64 = 0.05;

/// The pipeline of README.md's block marked `<!-- tests/live.rs: NAME -->`, as
/// `gst::parse::launch` takes it: continuation lines joined, `gst-launch-1.0 -e` removed.
fn recipe(name: &str) -> String {
    let readme = std::fs::read_to_string(checkout().join("README.md")).expect("README.md");
    let marker = format!("<!-- tests/live.rs: {name} -->");
    let after = readme
        .split_once(&marker)
        .unwrap_or_else(|| panic!("README.md has no block marked {marker}"))
        .1;
    let block = after
        .trim_start()
        .strip_prefix("```")
        .and_then(|b| b.split_once('\n'))
        .unwrap_or_else(|| panic!("{marker} is not followed by a fenced block"))
        .1;
    let body = block.split("```").next().expect("a closing fence");
    let line = body
        .lines()
        .map(|l| l.trim().trim_end_matches('\\').trim())
        .collect::<Vec<_>>()
        .join(" ");
    line.strip_prefix("gst-launch-1.0 -e ")
        .unwrap_or(&line)
        .trim()
        .to_string()
}

/// Swaps each device for its stand-in; every one named must be in the recipe, so a
/// README edit that changes a device fails here rather than testing something else.
fn stand_ins(recipe: &str, swaps: &[(&str, &str)]) -> String {
    swaps
        .iter()
        .fold(recipe.to_string(), |r, (device, stand_in)| {
            assert!(
                r.contains(device),
                "the README recipe no longer has `{device}`: {recipe}"
            );
            r.replace(device, stand_in)
        })
}

/// The webcam's frames: the shipped recording decoded once, I420 at WIDTH x HEIGHT.
fn recording() -> &'static [gst::Buffer] {
    footage(WIDTH, HEIGHT)
}

/// Memory the decoded frames of one size may take: a 2160p camera loops a clip of
/// about a second rather than the whole recording.
const FOOTAGE_BYTES: usize = 400 << 20;

/// The shipped recording decoded once per size, I420 at `width` x `height` (scaled
/// up for the high-resolution runs), at most [`FOOTAGE_BYTES`] of it.
fn footage(width: i32, height: i32) -> &'static [gst::Buffer] {
    type Cache = Mutex<Vec<((i32, i32), &'static [gst::Buffer])>>;
    static FRAMES: OnceLock<Cache> = OnceLock::new();
    let mut cache = FRAMES.get_or_init(Cache::default).lock().unwrap();
    if let Some((_, frames)) = cache.iter().find(|(size, _)| *size == (width, height)) {
        return frames;
    }
    init();
    let face = checkout().join("examples/data/call/face.mp4");
    let pipeline = gst::parse::launch(&format!(
        "filesrc location=\"{}\" ! decodebin ! videoconvert ! videoscale ! \
         video/x-raw,format=I420,width={width},height={height} ! appsink name=frames sync=false",
        face.display()
    ))
    .unwrap()
    .downcast::<gst::Pipeline>()
    .unwrap();
    let sink = pipeline
        .by_name("frames")
        .unwrap()
        .downcast::<gst_app::AppSink>()
        .unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let limit = FOOTAGE_BYTES / (width * height * 3 / 2) as usize;
    let mut frames = Vec::new();
    while frames.len() < limit
        && let Ok(sample) = sink.pull_sample()
    {
        frames.push(sample.buffer_owned().unwrap());
    }
    pipeline.set_state(gst::State::Null).unwrap();
    assert!(frames.len() >= 30, "decoded {} frames", frames.len());
    let frames: &'static [gst::Buffer] = Vec::leak(frames);
    cache.push(((width, height), frames));
    frames
}

/// A camera: pushes the recording at `width` x `height`, looped, at `fps` in real
/// time, timestamped by the clock on arrival as `v4l2src` does. Returns how many
/// frames it pushed.
fn camera(
    src: gst_app::AppSrc,
    (width, height): (i32, i32),
    fps: u32,
    stop: Arc<AtomicBool>,
) -> thread::JoinHandle<u64> {
    let caps = gst::Caps::builder("video/x-raw")
        .field("format", "I420")
        .field("width", width)
        .field("height", height)
        .field("framerate", gst::Fraction::new(fps as i32, 1))
        .build();
    src.set_caps(Some(&caps));
    src.set_is_live(true);
    src.set_do_timestamp(true);
    src.set_format(gst::Format::Time);
    // v4l2src reports one frame of latency: the frame is complete a frame after it began.
    src.set_latency(gst::ClockTime::SECOND / fps as u64, None);
    let frames = footage(width, height);
    thread::spawn(move || {
        // do-timestamp needs the clock, which the source has once it plays.
        while src.current_state() != gst::State::Playing {
            if stop.load(Ordering::Relaxed) {
                return 0;
            }
            thread::sleep(Duration::from_millis(1));
        }
        let period = Duration::from_secs(1) / fps;
        let start = Instant::now();
        let mut pushed = 0u64;
        while !stop.load(Ordering::Relaxed) {
            let due = start + period * pushed as u32;
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                thread::sleep(wait);
            }
            let mut frame = frames[pushed as usize % frames.len()].copy();
            let b = frame.get_mut().unwrap();
            b.set_pts(None);
            b.set_dts(None);
            b.set_duration(gst::ClockTime::SECOND / fps as u64);
            if src.push_buffer(frame).is_err() {
                break;
            }
            pushed += 1;
        }
        let _ = src.end_of_stream();
        pushed
    })
}

/// What one sink saw: for each frame, when it arrived (running time) and how much
/// after its own running time.
#[derive(Default)]
struct Arrivals {
    at_ms: Vec<f64>,
    delay_ms: Vec<f64>,
}

/// Records the arrival of every buffer at `sink` against the pipeline clock, and
/// drains it as a display would (syncing, dropping what is too late).
fn watch(pipeline: &gst::Pipeline, sink: &str) -> Arc<Mutex<Arrivals>> {
    let sink = watched_sink(pipeline, sink);
    sink.set_sync(true);
    // obs-gstreamer's appsink syncs but keeps late frames; video sinks drop them.
    if sink.name() != OBS_SINK {
        sink.set_qos(true);
        sink.set_max_lateness(MAX_LATENESS.nseconds() as i64);
    }
    sink.set_callbacks(
        gst_app::AppSinkCallbacks::builder()
            .new_sample(|s| {
                s.pull_sample().map_err(|_| gst::FlowError::Eos)?;
                Ok(gst::FlowSuccess::Ok)
            })
            .build(),
    );
    let arrivals = Arc::new(Mutex::new(Arrivals::default()));
    let record = arrivals.clone();
    let element = sink.clone().upcast::<gst::Element>();
    sink.static_pad("sink")
        .unwrap()
        .add_probe(gst::PadProbeType::BUFFER, move |pad, info| {
            let (Some(buffer), Some(clock), Some(base)) =
                (info.buffer(), element.clock(), element.base_time())
            else {
                return gst::PadProbeReturn::Ok;
            };
            let segment = pad.sticky_event::<gst::event::Segment>(0);
            let rt = segment.and_then(|s| {
                s.segment()
                    .downcast_ref::<gst::ClockTime>()?
                    .to_running_time(buffer.pts()?)
            });
            if let Some(rt) = rt {
                let now = clock.time();
                let now_ms = now.saturating_sub(base).nseconds() as f64 / 1e6;
                let mut a = record.lock().unwrap();
                a.at_ms.push(now_ms);
                a.delay_ms.push(now_ms - rt.nseconds() as f64 / 1e6);
            }
            gst::PadProbeReturn::Ok
        });
    arrivals
}

/// Frames dropped for lateness, by QoS (a sink, or `videoconvert` told by the
/// sink's QoS events), from the QoS messages each drop posts.
#[derive(Default)]
struct Drops {
    /// Each element's count so far (the messages carry running totals).
    total: std::collections::HashMap<String, u64>,
    /// Drops of frames after the first WARM_UP of the run.
    after_warm_up: u64,
}

/// The start of a run, when frames that queued while the model loaded may be dropped.
const WARM_UP: gst::ClockTime = gst::ClockTime::from_seconds(5);

impl Drops {
    fn count(&mut self, qos: &gst::message::Qos) {
        let (_, dropped) = qos.stats();
        let (_, running_time, _, _, _) = qos.get();
        let Some(src) = qos.src() else { return };
        let dropped = dropped.value().max(0) as u64;
        let before = self.total.insert(src.name().to_string(), dropped);
        if dropped > before.unwrap_or(0) && running_time.is_some_and(|t| t >= WARM_UP) {
            self.after_warm_up += dropped - before.unwrap_or(0);
        }
    }

    fn total(&self) -> u64 {
        self.total.values().sum()
    }
}

fn watched_sink(pipeline: &gst::Pipeline, name: &str) -> gst_app::AppSink {
    pipeline
        .by_name(name)
        .unwrap_or_else(|| panic!("no {name} in the pipeline"))
        .downcast::<gst_app::AppSink>()
        .unwrap()
}

/// Whether this machine is too busy for a real-time run to say anything about the
/// element: a 1-minute load average above 1.5 per core (other jobs' threads queue for
/// every core). LSYDRELIGHT_LIVE_STRICT=1 checks real time regardless.
fn overload() -> Option<String> {
    if std::env::var_os("LSYDRELIGHT_LIVE_STRICT").is_some() {
        return None;
    }
    let load: f64 = std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()?;
    let cores = thread::available_parallelism().map_or(1, |n| n.get());
    (load > 1.5 * cores as f64).then(|| format!("load average {load:.1} on {cores} cores"))
}

fn median(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty(), "no frames in the window");
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One run of a recipe: the pipeline plays for `seconds` while cameras push.
struct Run {
    name: String,
    pushed: u64,
    sinks: Vec<(String, Arc<Mutex<Arrivals>>)>,
    drops: Drops,
    /// Whether every frame had reached the sinks or been dropped 20 s after the end.
    drained: bool,
    /// Why the machine could not give the run real time, if it could not.
    overload: Option<String>,
    seconds: u64,
    first_frame: Duration,
    latency: gst::ClockTime,
    stats: gst::Structure,
    /// The share of frames the element must relight or carry by its reuse
    /// interval, not reuse for lateness (QoS), when the run checks it.
    min_in_time: Option<f64>,
    /// The share of frames the sinks may drop for lateness after the first WARM_UP.
    max_dropped: f64,
    /// Whether the element must keep denoising: a camera it can afford does
    /// not lose it to the element's overload guard.
    keeps_denoising: bool,
}

impl Run {
    fn play(name: &str, description: &str, sinks: &[&str], fps: u32, seconds: u64) -> Run {
        Run::play_at(name, description, sinks, fps, seconds, (WIDTH, HEIGHT))
    }

    /// [`Run::play`] with a camera of `size`.
    fn play_at(
        name: &str,
        description: &str,
        sinks: &[&str],
        fps: u32,
        seconds: u64,
        size: (i32, i32),
    ) -> Run {
        init();
        // Decoded before the clock starts.
        footage(size.0, size.1);
        let pipeline = gst::parse::launch(description)
            .unwrap_or_else(|e| panic!("{name}: {e}: {description}"))
            .downcast::<gst::Pipeline>()
            .unwrap();
        let watched: Vec<_> = sinks.iter().map(|s| watch(&pipeline, s)).collect();
        let relight = pipeline
            .iterate_recurse()
            .into_iter()
            .flatten()
            .find(|e| e.factory().is_some_and(|f| f.name() == "lsydrelight"))
            .expect("the recipe has lsydrelight");
        let (first_tx, first_rx) = std::sync::mpsc::channel();
        let first_tx = Mutex::new(Some(first_tx));
        relight
            .static_pad("src")
            .unwrap()
            .add_probe(gst::PadProbeType::BUFFER, move |_, _| {
                if let Some(tx) = first_tx.lock().unwrap().take() {
                    let _ = tx.send(Instant::now());
                }
                gst::PadProbeReturn::Ok
            });
        let stop = Arc::new(AtomicBool::new(false));
        let webcam = pipeline
            .by_name("webcam")
            .unwrap()
            .downcast::<gst_app::AppSrc>()
            .unwrap();
        let camera = camera(webcam, size, fps, stop.clone());
        let started = Instant::now();
        pipeline.set_state(gst::State::Playing).unwrap();
        let first = first_rx
            .recv_timeout(Duration::from_secs(10))
            .unwrap_or_else(|_| panic!("{name}: no relit frame within 10 s"));
        let bus = pipeline.bus().unwrap();
        let relight_name = relight.name();
        let mut drops = Drops::default();
        let watch_bus = |until: Instant, drops: &mut Drops| -> bool {
            while let Some(wait) = until.checked_duration_since(Instant::now()) {
                let Some(msg) = bus.timed_pop_filtered(
                    gst::ClockTime::from_nseconds(wait.as_nanos() as u64),
                    &[
                        gst::MessageType::Error,
                        gst::MessageType::Qos,
                        gst::MessageType::Eos,
                    ],
                ) else {
                    continue;
                };
                match msg.view() {
                    gst::MessageView::Error(e) => {
                        panic!("{name}: {} ({:?})", e.error(), e.debug())
                    }
                    gst::MessageView::Eos(_) => return true,
                    // lsydrelight's own QoS messages count frames it gave a reused
                    // relighting: late, but delivered.
                    gst::MessageView::Qos(q)
                        if msg.src().is_some_and(|s| s.name() != relight_name) =>
                    {
                        drops.count(q)
                    }
                    _ => {}
                }
            }
            false
        };
        assert!(
            !watch_bus(started + Duration::from_secs(seconds), &mut drops),
            "{name}: ended early"
        );
        let mut query = gst::query::Latency::new();
        let sink_pad = watched_sink(&pipeline, sinks[0])
            .static_pad("sink")
            .unwrap();
        assert!(sink_pad.peer_query(&mut query), "{name}: latency query");
        let (live, latency, _) = query.result();
        assert!(live, "{name}: the pipeline is live");
        let load = overload();
        // As `gst-launch-1.0 -e` stops: end of stream from every source, then wait
        // until every frame pushed has reached the sinks or been dropped.
        stop.store(true, Ordering::Relaxed);
        let pushed = camera.join().unwrap();
        for source in pipeline.iterate_sources().into_iter().flatten() {
            if source.name() != "webcam" {
                source.send_event(gst::event::Eos::new());
            }
        }
        let drained = watch_bus(Instant::now() + Duration::from_secs(20), &mut drops);
        let stats = relight.property::<gst::Structure>("stats");
        pipeline.set_state(gst::State::Null).unwrap();
        Run {
            name: name.to_string(),
            pushed,
            sinks: sinks.iter().map(|s| s.to_string()).zip(watched).collect(),
            drops,
            drained,
            overload: load.or_else(overload),
            seconds,
            first_frame: first.duration_since(started),
            latency,
            stats,
            min_in_time: None,
            max_dropped: DROPPED_SHARE,
            keeps_denoising: true,
        }
    }

    /// The recipe works: the face is found and every frame pushed reached every
    /// sink or was dropped by QoS. Real time kept (unless the machine is overloaded,
    /// see [`overload`]): few frames dropped after the start-up, and the lateness at
    /// the sink no greater at the end than at the start (10 s windows, a third of a
    /// shorter run).
    fn check(&self) {
        let name = &self.name;
        eprintln!(
            "{name}: {} frames pushed, first frame after {:?}, latency {}, {} dropped by QoS \
             ({} after {WARM_UP}); element {}",
            self.pushed,
            self.first_frame,
            self.latency,
            self.drops.total(),
            self.drops.after_warm_up,
            self.stats
        );
        let frames = self.stats.get::<u64>("frames").unwrap();
        let faced = frames - self.stats.get::<u64>("skipped-no-face").unwrap();
        assert!(
            faced * 5 >= frames * 4,
            "{name}: a face in only {faced} of {frames} frames"
        );
        let mut late = Vec::new();
        for (sink, arrivals) in &self.sinks {
            let a = arrivals.lock().unwrap();
            let arrived = a.at_ms.len() as u64;
            // The run, without the frames that drained after it.
            let end = self.seconds as f64 * 1e3;
            let window = |from: f64, to: f64| -> f64 {
                median(
                    a.at_ms
                        .iter()
                        .zip(&a.delay_ms)
                        .filter(|(t, _)| (from..to.min(end)).contains(*t))
                        .map(|(_, d)| *d)
                        .collect(),
                )
            };
            let span = (self.seconds as f64 / 3.0).min(10.0) * 1e3;
            let start = a.at_ms[0];
            let (first, last) = (window(start, start + span), window(end - span, end));
            let mut sorted = a.delay_ms.clone();
            sorted.sort_by(f64::total_cmp);
            eprintln!(
                "{name} {sink}: {arrived} arrived; after their running time: median {first:.1} ms \
                 at the start, {last:.1} ms at the end, p90 {:.1} ms, max {:.1} ms",
                sorted[sorted.len() * 9 / 10],
                sorted[sorted.len() - 1]
            );
            if self.drained {
                assert!(
                    arrived + self.drops.total() >= self.pushed,
                    "{name} {sink}: of {} frames, {arrived} arrived and {} were dropped by QoS; \
                     the rest were lost",
                    self.pushed,
                    self.drops.total()
                );
            }
            if last > first + GROWTH_MARGIN_MS {
                late.push(format!(
                    "{sink}: frames arrive later and later: median {first:.1} ms after their \
                     time at the start, {last:.1} ms at the end"
                ));
            }
        }
        let shown = self.pushed * self.sinks.len() as u64;
        if self.drops.after_warm_up as f64 > self.max_dropped * shown as f64 {
            late.push(format!(
                "{} of {shown} frames dropped for lateness after the first {WARM_UP}",
                self.drops.after_warm_up
            ));
        }
        if !self.drained {
            late.push("frames still queued 20 s after the end".into());
        }
        let reused = self.stats.get::<u64>("qos-reused").unwrap();
        let in_time = frames - reused;
        eprintln!(
            "{name}: {in_time} of {frames} frames relit or carried in time ({} by the \
             network), {reused} reused for lateness",
            self.stats.get::<u64>("relit").unwrap()
        );
        if let Some(share) = self.min_in_time
            && (in_time as f64) < share * frames as f64
        {
            late.push(format!(
                "only {in_time} of {frames} frames relit in time; {reused} were late and \
                 reused the last relighting"
            ));
        }
        if self.keeps_denoising && self.stats.get::<bool>("denoising-dropped").unwrap() {
            late.push("frames cost so much of their period that the denoising was dropped".into());
        }
        match &self.overload {
            Some(why) if !late.is_empty() => eprintln!(
                "{name}: real time not checked, the machine is overloaded ({why}): {}",
                late.join("; ")
            ),
            _ => assert!(late.is_empty(), "{name}: {}", late.join("; ")),
        }
    }
}

/// The live tests run one at a time: each needs the cores to itself to keep real time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// README's webcam-and-screen recipe into a window and the virtual camera, at
/// 30 and 60 fps at once, for a minute each.
#[test]
fn virtual_camera_recipe_keeps_real_time_for_a_minute_at_30_and_60_fps() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let pipeline = stand_ins(
        &recipe("virtual-camera"),
        &[
            ("v4l2src device=/dev/video0", "appsrc name=webcam"),
            (
                "ximagesrc use-damage=false",
                "videotestsrc is-live=true pattern=smpte",
            ),
            ("autovideosink", "appsink name=window"),
            (
                "v4l2sink device=/dev/video10",
                "appsink name=virtual-camera",
            ),
        ],
    );
    recording();
    let runs: Vec<_> = [30, 60]
        .into_iter()
        .map(|fps| {
            let pipeline = pipeline.clone();
            thread::spawn(move || {
                let name = format!("virtual camera at {fps} fps");
                Run::play(&name, &pipeline, &["window", "virtual-camera"], fps, 60)
            })
        })
        .collect();
    for run in runs {
        let run = run.join().unwrap();
        run.check();
        assert!(
            run.stats.get::<u64>("known-source").unwrap() > 0,
            "{}: the screen's light was never used",
            run.name
        );
    }
}

/// README's unknown-source recipe (no screen) and its OBS GStreamer Source
/// pipeline, built and started twice in one process as obs-gstreamer does when
/// the source is hidden and shown.
#[test]
fn unknown_source_and_obs_recipes_keep_real_time_and_restart() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let camera = ("v4l2src device=/dev/video0", "appsrc name=webcam");
    let unknown = stand_ins(
        &recipe("unknown-source"),
        &[
            camera,
            (
                "v4l2sink device=/dev/video10",
                "appsink name=virtual-camera",
            ),
        ],
    );
    // obs-gstreamer adds its sinks in front of the user's pipeline: `video` is a videoconvert.
    let obs_recipe = recipe("obs");
    assert!(
        obs_recipe.ends_with("! video."),
        "the OBS pipeline must end in `video.`: {obs_recipe}"
    );
    let obs = format!("{OBS_VIDEO} {}", stand_ins(&obs_recipe, &[camera]));
    recording();
    let unknown_run =
        thread::spawn(move || Run::play("unknown source", &unknown, &["virtual-camera"], 30, 20));
    let obs_runs: Vec<Run> = (1..=2)
        .map(|start| Run::play(&format!("OBS start {start}"), &obs, &[OBS_SINK], 30, 10))
        .collect();
    let unknown_run = unknown_run.join().unwrap();
    unknown_run.check();
    for run in &obs_runs {
        if run.overload.is_none() {
            assert!(
                run.first_frame < Duration::from_secs(2),
                "{}: the first frame took {:?}",
                run.name,
                run.first_frame
            );
        }
        run.check();
        assert_eq!(run.stats.get::<u64>("known-source").unwrap(), 0);
    }
}

/// `ximagesrc` as the recipes have it.
const SCREEN: &str = "ximagesrc use-damage=false ! video/x-raw,framerate=10/1";
/// A small live test screen in its place.
const SMALL_TEST_SCREEN: &str =
    "videotestsrc is-live=true pattern=smpte ! video/x-raw,framerate=10/1";
/// A full-HD live test screen in its place, in the size and format (BGRx)
/// that `ximagesrc` gives. Each monitor frame's light is read from every one
/// of its pixels on the element's thread, so a small screen leaves that cost
/// out.
const FULL_HD_TEST_SCREEN: &str = "videotestsrc is-live=true pattern=smpte ! \
     video/x-raw,format=BGRx,width=1920,height=1080,framerate=10/1";

/// How long the high-resolution and four-instance runs play: a minute each in the
/// suite; LSYDRELIGHT_LIVE_SECONDS runs them longer by hand. Those runs need the
/// optimised build (the unoptimised test build pastes a 2160p frame in about 100 ms,
/// 15 times the release build): `scripts/test.sh` runs them with `--release`.
fn live_seconds() -> u64 {
    std::env::var("LSYDRELIGHT_LIVE_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60)
}

/// README's high-resolution recipe with a 1080p camera, then a 2160p one, each
/// at 30 fps for a minute: real time held (few frames dropped, the latency not
/// growing, every frame accounted for), and for the 1080p camera at least 95% of
/// frames relit in time (not reused for lateness). The 2160p run prints its
/// share but does not assert it, and may drop up to 5% rather than 1%: on two
/// cores without AVX-512 a 2160p frame round a close face takes about 33 ms, its
/// whole period, so the share in time is that machine's speed, whose parts the
/// benchmark's stage table measures (docs/live.md); what must
/// hold there is that QoS keeps the stream in real time, not falling behind. The 1080p run's screen is full HD; the 2160p
/// run's a small one, as its margin on a 2-core machine does not cover a
/// full-HD screen's light.
#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "needs an optimised build: cargo test --release --test live"
)]
fn a_1080p_and_a_2160p_camera_keep_real_time_at_30_fps() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let recipe = recipe("high-resolution");
    // 2160p on 2 cores cannot afford the denoising: the element drops it.
    for (width, height, screen, min_in_time, max_dropped, keeps_denoising) in [
        (
            1920,
            1080,
            FULL_HD_TEST_SCREEN,
            Some(0.95),
            DROPPED_SHARE,
            true,
        ),
        (
            3840,
            2160,
            SMALL_TEST_SCREEN,
            None,
            DROPPED_SHARE_AT_LIMIT,
            false,
        ),
    ] {
        let pipeline = stand_ins(
            &recipe,
            &[
                ("v4l2src device=/dev/video0", "appsrc name=webcam"),
                (
                    "width=1920,height=1080",
                    &format!("width={width},height={height}"),
                ),
                (SCREEN, screen),
                ("autovideosink", "appsink name=window"),
            ],
        );
        let name = format!("{height}p camera at 30 fps");
        let mut run = Run::play_at(
            &name,
            &pipeline,
            &["window"],
            30,
            live_seconds(),
            (width, height),
        );
        run.min_in_time = min_in_time;
        run.max_dropped = max_dropped;
        run.keeps_denoising = keeps_denoising;
        run.check();
    }
}

/// Four calls in one process: four instances of the element, each relighting its
/// own 480p camera at 30 fps at once, each holding real time for a minute.
#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "needs an optimised build: cargo test --release --test live"
)]
fn four_instances_at_480p_each_keep_30_fps() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let pipeline = stand_ins(
        &recipe("high-resolution"),
        &[
            ("v4l2src device=/dev/video0", "appsrc name=webcam"),
            ("width=1920,height=1080", "width=854,height=480"),
            (SCREEN, SMALL_TEST_SCREEN),
            ("autovideosink", "appsink name=window"),
        ],
    );
    footage(854, 480);
    let runs: Vec<_> = (1..=4)
        .map(|call| {
            let pipeline = pipeline.clone();
            thread::spawn(move || {
                let name = format!("480p call {call} of 4");
                Run::play_at(
                    &name,
                    &pipeline,
                    &["window"],
                    30,
                    live_seconds(),
                    (854, 480),
                )
            })
        })
        .collect();
    for run in runs {
        let mut run = run.join().unwrap();
        run.min_in_time = Some(0.95);
        run.check();
    }
}
