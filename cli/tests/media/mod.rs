//! Test recordings and how to read them back. The inputs are the simulator's
//! call (the person at a desk, lit by the monitor) at 160x120, encoded by real
//! GStreamer encoders into MP4 (H.264 + AAC) and MKV (H.264 + Opus), so the
//! tool meets the files a call recorder writes.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use deskstage::dataset::{Recording, RecordingSpec};
use deskstage::monitor::RgbImage;
use gst::prelude::*;

pub const FPS: i32 = 30;
/// Frames of the short recordings.
pub const FRAMES: usize = 60;
/// Frames of the long one, long enough to interrupt while it is relit.
pub const LONG_FRAMES: usize = 900;

pub struct Fixtures {
    /// Face video with AAC audio in MP4.
    pub face_mp4: PathBuf,
    /// Face video with Opus audio in MKV.
    pub face_mkv: PathBuf,
    /// Face video, `LONG_FRAMES` long, with AAC audio in MP4.
    pub long_mp4: PathBuf,
    /// What the monitor showed, in MP4 (video only, as a screen recorder writes it).
    pub screen_mp4: PathBuf,
    /// Opus audio alone in MKV: a recording without video.
    pub voice_mkv: PathBuf,
}

/// The recordings, made once per test run.
pub fn fixtures() -> &'static Fixtures {
    static FIXTURES: OnceLock<Fixtures> = OnceLock::new();
    FIXTURES.get_or_init(|| {
        gst::init().expect("GStreamer initialises");
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("relight-inputs");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("fixture folder");
        let (faces, screens) = render();
        let f = Fixtures {
            face_mp4: dir.join("face.mp4"),
            face_mkv: dir.join("face.mkv"),
            long_mp4: dir.join("long.mp4"),
            screen_mp4: dir.join("screen.mp4"),
            voice_mkv: dir.join("voice.mkv"),
        };
        encode(&f.face_mp4, &faces, FRAMES, Some("avenc_aac"), "mp4mux");
        encode(&f.face_mkv, &faces, FRAMES, Some("opusenc"), "matroskamux");
        encode(
            &f.long_mp4,
            &faces,
            LONG_FRAMES,
            Some("avenc_aac"),
            "mp4mux",
        );
        encode(&f.screen_mp4, &screens, FRAMES, None, "mp4mux");
        encode(&f.voice_mkv, &[], 0, Some("opusenc"), "matroskamux");
        f
    })
}

/// The simulator's call: face frames and the monitor frames that lit them.
fn render() -> (Vec<RgbImage>, Vec<RgbImage>) {
    let mut spec = RecordingSpec::standard("call").expect("the call recording");
    spec.width = 160;
    spec.height = 120;
    spec.frames = FRAMES;
    let rec = Recording::new(spec).expect("the simulator renders");
    (0..FRAMES)
        .map(|i| {
            let f = rec.frame(i, false);
            (f.face, f.monitor)
        })
        .unzip()
}

/// Encodes `frames` video frames (cycling through `images`) to H.264 with, when
/// `audio_encoder` is given, as long a tone encoded by it, into `muxer`.
/// With no frames, only the audio: 2 seconds of it.
fn encode(
    path: &Path,
    images: &[RgbImage],
    frames: usize,
    audio_encoder: Option<&str>,
    muxer: &str,
) {
    let seconds = if frames > 0 {
        frames as f64 / FPS as f64
    } else {
        2.0
    };
    let video = match images.first() {
        Some(img) => format!(
            "appsrc name=video format=time caps=video/x-raw,format=RGB,width={},height={},framerate={FPS}/1 \
             ! videoconvert ! x264enc speed-preset=ultrafast ! mux.",
            img.width, img.height
        ),
        None => String::new(),
    };
    let audio = match audio_encoder {
        // 1024 samples a buffer at 48 kHz.
        Some(enc) => format!(
            "audiotestsrc num-buffers={} samplesperbuffer=1024 wave=ticks ! audio/x-raw,rate=48000,channels=1 \
             ! audioconvert ! {enc} ! mux.",
            (seconds * 48000.0 / 1024.0).ceil() as usize
        ),
        None => String::new(),
    };
    let desc = format!(
        "{muxer} name=mux ! filesink location={} {video} {audio}",
        path.display()
    );
    let pipeline = gst::parse::launch(&desc)
        .expect("fixture pipeline")
        .downcast::<gst::Pipeline>()
        .expect("a pipeline");
    pipeline.set_state(gst::State::Playing).expect("plays");
    if let Some(src) = pipeline.by_name("video") {
        let src = src.downcast::<gst_app::AppSrc>().expect("appsrc");
        let frame_ns = 1_000_000_000 / FPS as u64;
        for i in 0..frames {
            let img = &images[i % images.len()];
            let mut buffer = gst::Buffer::from_slice(img.data.clone());
            let b = buffer.get_mut().expect("a new buffer is writable");
            b.set_pts(gst::ClockTime::from_nseconds(i as u64 * frame_ns));
            b.set_duration(gst::ClockTime::from_nseconds(frame_ns));
            src.push_buffer(buffer)
                .expect("the encoder takes the frame");
        }
        src.end_of_stream().expect("end of stream");
    }
    wait_eos(&pipeline);
}

fn wait_eos(pipeline: &gst::Pipeline) {
    let bus = pipeline.bus().expect("bus");
    let msg = bus
        .timed_pop_filtered(
            gst::ClockTime::from_seconds(120),
            &[gst::MessageType::Eos, gst::MessageType::Error],
        )
        .expect("the pipeline ends");
    if let gst::MessageView::Error(e) = msg.view() {
        panic!("{}: {:?}", e.error(), e.debug());
    }
    pipeline.set_state(gst::State::Null).expect("stops");
}

/// The encoded audio packets of a file as its demuxer gives them, before any parser.
pub fn audio_packets(path: &Path) -> Vec<Vec<u8>> {
    demuxed(path, "audio/")
        .into_iter()
        .map(|(_, data)| data)
        .collect()
}

/// The media type of the first stream whose type starts with `prefix`, as demuxed.
pub fn stream_type(path: &Path, prefix: &str) -> Option<String> {
    demuxed(path, prefix).first().map(|(t, _)| t.clone())
}

/// (media type, payload) of every packet of the streams of type `prefix`, from
/// the file's demuxer (qtdemux or matroskademux, by extension).
fn demuxed(path: &Path, prefix: &str) -> Vec<(String, Vec<u8>)> {
    gst::init().expect("GStreamer initialises");
    let demuxer = match path.extension().and_then(|e| e.to_str()) {
        Some("mp4") => "qtdemux",
        Some("mkv") => "matroskademux",
        e => panic!("no demuxer for {e:?}"),
    };
    let pipeline = gst::parse::launch(&format!(
        "filesrc location={} ! {demuxer} name=demux",
        path.display()
    ))
    .expect("demux pipeline")
    .downcast::<gst::Pipeline>()
    .expect("a pipeline");
    let packets = Arc::new(Mutex::new(Vec::new()));
    let demux = pipeline.by_name("demux").expect("demuxer");
    let (prefix, seen) = (prefix.to_string(), packets.clone());
    demux.connect_pad_added(move |demux, pad| {
        let caps = pad.current_caps().expect("demuxed caps");
        let kind = caps.structure(0).expect("a structure").name().to_string();
        let bin = demux.parent().and_downcast::<gst::Bin>().expect("in a bin");
        // A fakesink for the other streams: an appsink whose samples nobody pulls
        // holds back its end-of-stream.
        let wanted = kind.starts_with(&prefix);
        let sink = if wanted {
            let seen = seen.clone();
            let appsink = gst_app::AppSink::builder()
                .sync(false)
                .callbacks(
                    gst_app::AppSinkCallbacks::builder()
                        .new_sample(move |s| {
                            let sample = s.pull_sample().map_err(|_| gst::FlowError::Eos)?;
                            let map = sample
                                .buffer()
                                .expect("buffer")
                                .map_readable()
                                .expect("map");
                            seen.lock().unwrap().push((kind.clone(), map.to_vec()));
                            Ok(gst::FlowSuccess::Ok)
                        })
                        .build(),
                )
                .build();
            appsink.upcast::<gst::Element>()
        } else {
            gst::ElementFactory::make("fakesink")
                .property("sync", false)
                .build()
                .expect("fakesink")
        };
        // A queue each: the demuxer pushes every stream from one thread, and a sink
        // waiting to preroll would block the streams another sink waits for.
        let queue = gst::ElementFactory::make("queue").build().expect("queue");
        bin.add_many([&queue, &sink]).expect("add");
        queue.link(&sink).expect("link");
        sink.sync_state_with_parent().expect("sync");
        queue.sync_state_with_parent().expect("sync");
        pad.link(&queue.static_pad("sink").expect("sink pad"))
            .expect("link");
    });
    pipeline.set_state(gst::State::Playing).expect("plays");
    wait_eos(&pipeline);
    Arc::try_unwrap(packets)
        .map(|m| m.into_inner().unwrap())
        .unwrap_or_else(|a| a.lock().unwrap().clone())
}

/// Decodes a file's video: (frames, width, height). Panics where it does not play.
pub fn decode_video(path: &Path) -> (usize, u32, u32) {
    gst::init().expect("GStreamer initialises");
    let pipeline = gst::parse::launch(&format!(
        "filesrc location={} ! decodebin ! videoconvert ! appsink name=sink sync=false",
        path.display()
    ))
    .expect("decode pipeline")
    .downcast::<gst::Pipeline>()
    .expect("a pipeline");
    let sink = pipeline
        .by_name("sink")
        .and_downcast::<gst_app::AppSink>()
        .expect("appsink");
    pipeline.set_state(gst::State::Playing).expect("plays");
    let (mut frames, mut size) = (0, (0, 0));
    while let Some(sample) = sink.try_pull_sample(gst::ClockTime::from_seconds(60)) {
        let s = sample
            .caps()
            .expect("caps")
            .structure(0)
            .expect("structure")
            .to_owned();
        size = (
            s.get::<i32>("width").expect("width") as u32,
            s.get::<i32>("height").expect("height") as u32,
        );
        frames += 1;
    }
    let error = pipeline
        .bus()
        .and_then(|b| b.pop_filtered(&[gst::MessageType::Error]));
    pipeline.set_state(gst::State::Null).expect("stops");
    if let Some(m) = error
        && let gst::MessageView::Error(e) = m.view()
    {
        panic!(
            "{} does not play: {} ({:?})",
            path.display(),
            e.error(),
            e.debug()
        );
    }
    (frames, size.0, size.1)
}
