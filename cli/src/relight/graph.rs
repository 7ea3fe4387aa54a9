//! The pipeline that relights one recording:
//!
//! ```text
//! filesrc ! parsebin ┬ first video stream: decodebin ! videoconvert ! queue ! relight.sink
//!                    └ every other stream: queue ! mux            (parsed, never decoded)
//! filesrc ! decodebin ─ video: videoconvert ! queue ! relight.monitor_sink      (--screen)
//! relight.src ! queue ! videoconvert ! I420 ! x264enc ! mux ! filesink
//! relight.monitor_src ! queue ! videoconvert ! I420 ! x264enc ! mux ! filesink (--predicted-monitor)
//! ```
//!
//! Elements carry the names [`diagnose`](super::diagnose) reads to tell which
//! file an error is about: `face-*`, `screen-*`, `relight`, `out-*`, `predicted-*`.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use gst::prelude::*;

use super::job::{Files, Settings};
use super::target::Target;
use crate::exit::Failure;

/// The output container, chosen by the output's file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Container {
    Mp4,
    Mkv,
}

impl Container {
    pub fn of(path: &Path) -> Option<Container> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "mp4" => Some(Container::Mp4),
            "mkv" => Some(Container::Mkv),
            _ => None,
        }
    }

    pub fn extension(self) -> &'static str {
        match self {
            Container::Mp4 => "mp4",
            Container::Mkv => "mkv",
        }
    }

    fn muxer(self) -> &'static str {
        match self {
            Container::Mp4 => "mp4mux",
            Container::Mkv => "matroskamux",
        }
    }
}

/// Marks the errors this module posts itself: their text is already worded for the user.
pub const OWN_ERROR: &str = "lsydrelight-cli";

pub struct Graph {
    pub pipeline: gst::Pipeline,
    /// The element's face input, to ask upstream how long the recording is.
    face_sink: gst::Pad,
    /// Relit frames that left the element.
    frames: Arc<AtomicU64>,
    /// Predicted-monitor frames that left the element (not the gaps that stand
    /// for face frames without a prediction).
    predicted_frames: Arc<AtomicU64>,
}

impl Graph {
    pub fn frames(&self) -> u64 {
        self.frames.load(Ordering::Relaxed)
    }

    pub fn predicted_frames(&self) -> u64 {
        self.predicted_frames.load(Ordering::Relaxed)
    }

    /// The face recording's length in frames, once its duration and frame rate are known.
    pub fn expected_frames(&self) -> Option<u64> {
        let duration = self
            .face_sink
            .peer_query_duration::<gst::ClockTime>()?
            .nseconds();
        let caps = self.face_sink.current_caps()?;
        let rate = caps.structure(0)?.get::<gst::Fraction>("framerate").ok()?;
        let (n, d) = (rate.numer() as u128, rate.denom() as u128);
        (n > 0 && d > 0).then(|| (duration as u128 * n / (d * 1_000_000_000)) as u64)
    }
}

impl Drop for Graph {
    fn drop(&mut self) {
        let _ = self.pipeline.set_state(gst::State::Null);
    }
}

/// Builds the pipeline writing the relit video to `out` and the predicted
/// monitor to `predicted`: temporary names, whose containers follow `files`.
pub fn build(
    settings: &Settings,
    files: &Files,
    out: &Path,
    predicted: Option<&Path>,
) -> Result<Graph, Failure> {
    let pipeline = gst::Pipeline::new();
    let relight = make("lsydrelight", "relight")?;
    if let Some(model) = &settings.model {
        relight.set_property("model-location", utf8(model)?);
    }
    if let Some(target) = &settings.target {
        target.apply(&relight)?;
    }
    relight.set_property("monitor-offset", settings.monitor_offset_ns);
    pipeline.add(&relight).map_err(internal)?;

    let mux = encode(
        &pipeline,
        &relight,
        "src",
        "out",
        files.out.container,
        settings.quality,
        out,
    )?;
    face_input(&pipeline, &relight, &files.face, &mux, files.out.container)?;
    if let Some(screen) = &files.screen {
        video_input(&pipeline, &relight, screen, Side::Screen)?;
    }
    if let Some(Target::Video(video)) = &settings.target {
        video_input(&pipeline, &relight, video, Side::Target)?;
    }
    if let (Some(temp), Some(dest)) = (predicted, &files.predicted) {
        encode(
            &pipeline,
            &relight,
            "monitor_src",
            "predicted",
            dest.container,
            settings.quality,
            temp,
        )?;
    }

    let face_sink = relight
        .static_pad("sink")
        .ok_or_else(|| internal("no sink pad"))?;
    Ok(Graph {
        pipeline,
        face_sink,
        frames: count_buffers(&relight, "src")?,
        predicted_frames: count_buffers(&relight, "monitor_src")?,
    })
}

/// A count of the buffers leaving `element`'s pad `pad`.
fn count_buffers(element: &gst::Element, pad: &str) -> Result<Arc<AtomicU64>, Failure> {
    let count = Arc::new(AtomicU64::new(0));
    let counter = count.clone();
    element
        .static_pad(pad)
        .ok_or_else(|| internal(format!("no {pad} pad")))?
        .add_probe(gst::PadProbeType::BUFFER, move |_, _| {
            counter.fetch_add(1, Ordering::Relaxed);
            gst::PadProbeReturn::Ok
        });
    Ok(count)
}

/// `filesrc ! parsebin`: the first video stream is decoded into the element;
/// every other stream goes to the muxer as it is, so audio is never re-encoded.
fn face_input(
    pipeline: &gst::Pipeline,
    relight: &gst::Element,
    path: &Path,
    mux: &gst::Element,
    container: Container,
) -> Result<(), Failure> {
    let src = make("filesrc", "face-src")?;
    src.set_property("location", utf8(path)?);
    let parse = make("parsebin", "face-parse")?;
    let decode = make("decodebin", "face-decode")?;
    let convert = make("videoconvert", "face-convert")?;
    let queue = make("queue", "face-queue")?;
    pipeline
        .add_many([&src, &parse, &decode, &convert, &queue])
        .map_err(internal)?;
    src.link(&parse).map_err(internal)?;
    gst::Element::link_many([&convert, &queue]).map_err(internal)?;
    queue
        .link_pads(None, relight, Some("sink"))
        .map_err(internal)?;
    link_first_video(&decode, &convert);

    let video_taken = AtomicBool::new(false);
    let (pipeline_weak, decode_weak, mux_weak) =
        (pipeline.downgrade(), decode.downgrade(), mux.downgrade());
    parse.connect_pad_added(move |parse, pad| {
        let (Some(pipeline), Some(decode), Some(mux)) = (
            pipeline_weak.upgrade(),
            decode_weak.upgrade(),
            mux_weak.upgrade(),
        ) else {
            return;
        };
        let routed = if is_video(pad) && !video_taken.swap(true, Ordering::SeqCst) {
            decode
                .static_pad("sink")
                .ok_or_else(|| "decodebin has no sink pad".to_string())
                .and_then(|sink| pad.link(&sink).map(|_| ()).map_err(|e| e.to_string()))
        } else {
            keep_stream(&pipeline, pad, &mux, container)
        };
        if let Err(message) = routed {
            own_error(parse, gst::StreamError::Mux, &message);
        }
    });
    Ok(())
}

/// True for the face recording's list of streams when it holds no video.
/// parsebin posts the list as it exposes its pads (it has no no-more-pads
/// signal); without video the muxer would wait for relit frames forever.
pub fn face_without_video(message: &gst::Message) -> bool {
    let gst::MessageView::StreamCollection(c) = message.view() else {
        return false;
    };
    let from_face = message.src().is_some_and(|s| s.name() == "face-parse");
    from_face
        && !c
            .stream_collection()
            .iter()
            .any(|s| s.stream_type().contains(gst::StreamType::VIDEO))
}

/// A stream the tool does not relight, into the muxer through an unbounded
/// queue: the demuxer must never wait on it while the slow video branch catches
/// up (a file may interleave audio and video far apart).
fn keep_stream(
    pipeline: &gst::Pipeline,
    pad: &gst::Pad,
    mux: &gst::Element,
    container: Container,
) -> Result<(), String> {
    let caps = pad.current_caps().unwrap_or_else(|| pad.query_caps(None));
    let kind = media_type(&caps);
    let other = match container {
        Container::Mp4 => "write .mkv instead (Matroska holds almost any stream)",
        Container::Mkv => "convert that stream first",
    };
    let Some(mux_pad) = mux.compatible_pad(pad, Some(&caps)) else {
        return Err(format!(
            "its {kind} stream cannot be kept in {} without re-encoding; {other}",
            container.extension().to_uppercase()
        ));
    };
    let queue = gst::ElementFactory::make("queue")
        .property("max-size-buffers", 0u32)
        .property("max-size-bytes", 0u32)
        .property("max-size-time", 0u64)
        .build()
        .map_err(|e| e.to_string())?;
    pipeline.add(&queue).map_err(|e| e.to_string())?;
    let (Some(sink), Some(src)) = (queue.static_pad("sink"), queue.static_pad("src")) else {
        return Err("queue without pads".into());
    };
    src.link(&mux_pad)
        .map_err(|e| format!("{kind} into the muxer: {e}"))?;
    queue.sync_state_with_parent().map_err(|e| e.to_string())?;
    pad.link(&sink).map_err(|e| format!("{kind}: {e}"))?;
    Ok(())
}

/// A second video into the element: the screen recording, or a video target.
#[derive(Clone, Copy)]
enum Side {
    Screen,
    Target,
}

impl Side {
    /// The prefix of its elements' names (`diagnose` reads it) and its pad.
    fn names(self) -> (&'static str, &'static str, &'static str) {
        match self {
            Side::Screen => (
                "screen",
                "monitor_sink",
                "no video stream; pass the screen recording of what the monitor showed",
            ),
            Side::Target => (
                "target",
                "target_sink",
                "no video stream; pass a video whose frames are the target light",
            ),
        }
    }
}

/// `filesrc ! decodebin`: its video into the element's `monitor_sink` or
/// `target_sink`; other streams of the recording are not needed and are discarded.
fn video_input(
    pipeline: &gst::Pipeline,
    relight: &gst::Element,
    path: &Path,
    side: Side,
) -> Result<(), Failure> {
    let (prefix, pad, no_video) = side.names();
    let src = make("filesrc", &format!("{prefix}-src"))?;
    src.set_property("location", utf8(path)?);
    let decode = make("decodebin", &format!("{prefix}-decode"))?;
    let convert = make("videoconvert", &format!("{prefix}-convert"))?;
    let queue = make("queue", &format!("{prefix}-queue"))?;
    pipeline
        .add_many([&src, &decode, &convert, &queue])
        .map_err(internal)?;
    src.link(&decode).map_err(internal)?;
    gst::Element::link_many([&convert, &queue]).map_err(internal)?;
    queue
        .link_pads(None, relight, Some(pad))
        .map_err(internal)?;
    link_first_video(&decode, &convert);
    let convert_weak = convert.downgrade();
    decode.connect_no_more_pads(move |decode| {
        if convert_weak
            .upgrade()
            .and_then(|c| c.static_pad("sink"))
            .is_some_and(|p| !p.is_linked())
        {
            own_error(decode, gst::StreamError::WrongType, no_video);
        }
    });
    Ok(())
}

/// Links a decodebin's first raw video pad to `convert`; the rest go to fakesinks
/// (an unlinked pad would stop the demuxer feeding it with not-linked).
fn link_first_video(decode: &gst::Element, convert: &gst::Element) {
    let convert_weak = convert.downgrade();
    decode.connect_pad_added(move |decode, pad| {
        let Some(sink) = convert_weak.upgrade().and_then(|c| c.static_pad("sink")) else {
            return;
        };
        if is_video(pad) && !sink.is_linked() {
            if let Err(e) = pad.link(&sink) {
                own_error(decode, gst::StreamError::Format, &format!("video: {e}"));
            }
            return;
        }
        let discarded = gst::ElementFactory::make("fakesink")
            .property("sync", false)
            .property("async", false)
            .build();
        let Some(bin) = decode.parent().and_downcast::<gst::Bin>() else {
            return;
        };
        if let Ok(fakesink) = discarded
            && bin.add(&fakesink).is_ok()
            && let Some(fake_pad) = fakesink.static_pad("sink")
        {
            let _ = fakesink.sync_state_with_parent();
            let _ = pad.link(&fake_pad);
        }
    });
}

/// `queue ! videoconvert ! I420 ! x264enc ! mux ! filesink` from `relight`'s
/// `pad`; returns the muxer. I420 because players take little else in H.264.
fn encode(
    pipeline: &gst::Pipeline,
    relight: &gst::Element,
    pad: &str,
    prefix: &str,
    container: Container,
    quality: u32,
    location: &Path,
) -> Result<gst::Element, Failure> {
    let queue = make("queue", &format!("{prefix}-queue"))?;
    let convert = make("videoconvert", &format!("{prefix}-convert"))?;
    let i420 = make("capsfilter", &format!("{prefix}-format"))?;
    i420.set_property(
        "caps",
        gst::Caps::builder("video/x-raw")
            .field("format", "I420")
            .build(),
    );
    let x264 = make("x264enc", &format!("{prefix}-encode"))?;
    // Constant quality: `quantizer` is then x264's CRF.
    x264.set_property_from_str("pass", "qual");
    x264.set_property("quantizer", quality);
    let mux = make(container.muxer(), &format!("{prefix}-mux"))?;
    let sink = make("filesink", &format!("{prefix}-sink"))?;
    sink.set_property("location", utf8(location)?);
    pipeline
        .add_many([&queue, &convert, &i420, &x264, &mux, &sink])
        .map_err(internal)?;
    relight
        .link_pads(Some(pad), &queue, None)
        .map_err(internal)?;
    gst::Element::link_many([&queue, &convert, &i420, &x264, &mux, &sink]).map_err(internal)?;
    Ok(mux)
}

fn is_video(pad: &gst::Pad) -> bool {
    let caps = pad.current_caps().unwrap_or_else(|| pad.query_caps(None));
    let kind = media_type(&caps);
    // A still image is a one-frame video to decodebin.
    kind.starts_with("video/") || kind.starts_with("image/")
}

fn media_type(caps: &gst::CapsRef) -> String {
    caps.structure(0)
        .map(|s| s.name().to_string())
        .unwrap_or_else(|| "unknown".into())
}

/// Posts an error already worded for the user, marked as ours for `diagnose`.
fn own_error(element: &gst::Element, code: gst::StreamError, message: &str) {
    gst::element_error!(
        element,
        code,
        ("{}", message),
        details: gst::Structure::new_empty(OWN_ERROR)
    );
}

fn make(factory: &str, name: &str) -> Result<gst::Element, Failure> {
    gst::ElementFactory::make(factory)
        .name(name)
        .build()
        .map_err(|_| {
            let package = match factory {
                "x264enc" => "gstreamer1.0-plugins-ugly",
                "mp4mux" | "matroskamux" => "gstreamer1.0-plugins-good",
                "lsydrelight" => "this program, rebuilt",
                _ => "gstreamer1.0-plugins-base",
            };
            Failure::new(format!(
                "GStreamer's {factory} element is missing; install {package} (Debian's package name)"
            ))
        })
}

fn utf8(path: &Path) -> Result<&str, Failure> {
    path.to_str().ok_or_else(|| {
        Failure::new(format!(
            "{}: GStreamer takes only UTF-8 file names; rename it",
            path.display()
        ))
    })
}

/// A failure building the graph that no input can cause: a bug, stated as one.
fn internal(e: impl std::fmt::Display) -> Failure {
    Failure::new(format!("internal error building the pipeline: {e}"))
}
