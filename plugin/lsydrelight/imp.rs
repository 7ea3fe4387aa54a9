//! The `lsydrelight` element: an aggregator of the face stream and the monitor stream.
//!
//! The aggregator runs once per face frame. It consumes the monitor frames
//! shown up to the face frame's running time minus `monitor-offset`; the last
//! of them is the frame's source light. In a non-live pipeline it waits for
//! the monitor stream to show what comes next; in a live one it waits until
//! the aggregator's deadline. Without usable monitor content (no pad, not yet
//! started, stalled, or ended) it relights with the predicted light.
//!
//! `monitor_src` is driven by its own pad task fed from a small queue, so a
//! downstream sink that blocks in preroll on one output never blocks the other.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Condvar, LazyLock, Mutex, MutexGuard};

use gst::glib;
use gst::prelude::*;
use gst::subclass::prelude::*;
use gst_base::prelude::*;
use gst_base::subclass::prelude::*;
use gst_video::VideoFormat;
use gst_video::prelude::*;

use super::ExecutionProvider;
use crate::engine::contract::PRESENCE_SIZE;
use crate::engine::{self, FrameOutput, Provider, Relighter, Source, Temporal};
use crate::frame::{
    Crop, Frame, FrameMut, LightingChange, PixelFormat, Plane, YuvMatrix, sample_crop,
};
use crate::light::{LIGHT_COLS, LIGHT_ROWS, Light};
use crate::paths;

static CAT: LazyLock<gst::DebugCategory> = LazyLock::new(|| {
    gst::DebugCategory::new(
        "lsydrelight",
        gst::DebugColorFlags::empty(),
        Some("Personalised face relighting"),
    )
});

const FORMATS: [VideoFormat; 9] = [
    VideoFormat::I420,
    VideoFormat::Nv12,
    VideoFormat::Y444,
    VideoFormat::Rgba,
    VideoFormat::Bgra,
    VideoFormat::Rgbx,
    VideoFormat::Bgrx,
    VideoFormat::Rgb,
    VideoFormat::Bgr,
];

/// Smallest face frame: the crop and the lighting transfer need a few pixels to work with.
const MIN_FACE_SIZE: i32 = 16;
/// Size of the predicted-monitor video: each light cell becomes 8×8 pixels.
const MONITOR_SCALE: usize = 8;
/// Buffers `monitor_src` holds before it drops the oldest.
const MONITOR_QUEUE: usize = 8;

/// Reference-timestamp caps of the meta that names the monitor frame used.
pub static MONITOR_TIMESTAMP_CAPS: LazyLock<gst::Caps> =
    LazyLock::new(|| gst::Caps::new_empty_simple("timestamp/x-lsydrelight-monitor"));

const DEFAULT_THREADS: u32 = 2;
const DEFAULT_MONITOR_OFFSET: i64 = 0;
const MAX_MONITOR_OFFSET: i64 = 10_000_000_000;
const DEFAULT_MONITOR_TIMEOUT: gst::ClockTime = gst::ClockTime::from_seconds(1);
const DEFAULT_RESET_GAP: gst::ClockTime = gst::ClockTime::from_seconds(1);
const DEFAULT_CROP_CENTRE: f64 = 0.5;
const DEFAULT_CROP_SIZE: f64 = 1.0;
const DEFAULT_FEATHER: f64 = 0.06;
// The skips' defaults come from the benchmark's skip table (README, "Skipping what a
// scene does not need"): each is on where it pays within the error budget. The static
// skip never fired on a webcam recording (sensor noise and a person's small motions
// exceed its thresholds) and its check cost frames per second, so it is off.
const DEFAULT_SKIP_STATIC: bool = false;
/// Mean absolute change of the network's input (sRGB, [0, 1]) below which a frame reuses the last relighting.
const DEFAULT_STATIC_THRESHOLD: f64 = 0.004;
/// Mean absolute change of the averaged source light (linear) allowed for that reuse.
const DEFAULT_STATIC_LIGHT_THRESHOLD: f64 = 0.002;
const DEFAULT_SKIP_SAME_LIGHT: bool = true;
/// Mean absolute difference (linear light) under which source and target count as the same.
const DEFAULT_SAME_LIGHT_TOLERANCE: f64 = 0.004;
const DEFAULT_SKIP_ABSENT: bool = true;
const DEFAULT_PRESENCE_THRESHOLD: f64 = 0.5;
const DEFAULT_QOS: bool = true;

#[derive(Debug, Clone)]
struct Settings {
    model_location: PathBuf,
    ort_library: PathBuf,
    provider: ExecutionProvider,
    threads: u32,
    target_location: PathBuf,
    /// The target light, decoded when `target-location` is set (on the application's
    /// thread, so a change never stalls the stream); None until then or if it failed.
    target_light: Option<Arc<Light>>,
    /// Bumped whenever the target light changes, so the streaming thread encodes it.
    target_generation: u64,
    monitor_offset: i64,
    monitor_timeout: gst::ClockTime,
    temporal: Temporal,
    crop_x: f64,
    crop_y: f64,
    crop_size: f64,
    feather: f64,
    reset_gap: gst::ClockTime,
    skip_static: bool,
    static_threshold: f64,
    static_light_threshold: f64,
    skip_same_light: bool,
    same_light_tolerance: f64,
    skip_absent: bool,
    presence_threshold: f64,
    qos: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            model_location: paths::default_model(),
            ort_library: paths::default_ort_library(),
            provider: ExecutionProvider::Cpu,
            threads: DEFAULT_THREADS,
            target_location: paths::default_target(),
            target_light: None,
            target_generation: 0,
            monitor_offset: DEFAULT_MONITOR_OFFSET,
            monitor_timeout: DEFAULT_MONITOR_TIMEOUT,
            temporal: Temporal::default(),
            crop_x: DEFAULT_CROP_CENTRE,
            crop_y: DEFAULT_CROP_CENTRE,
            crop_size: DEFAULT_CROP_SIZE,
            feather: DEFAULT_FEATHER,
            reset_gap: DEFAULT_RESET_GAP,
            skip_static: DEFAULT_SKIP_STATIC,
            static_threshold: DEFAULT_STATIC_THRESHOLD,
            static_light_threshold: DEFAULT_STATIC_LIGHT_THRESHOLD,
            skip_same_light: DEFAULT_SKIP_SAME_LIGHT,
            same_light_tolerance: DEFAULT_SAME_LIGHT_TOLERANCE,
            skip_absent: DEFAULT_SKIP_ABSENT,
            presence_threshold: DEFAULT_PRESENCE_THRESHOLD,
            qos: DEFAULT_QOS,
        }
    }
}

/// Why a frame is relit with the predicted source light.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fallback {
    NoMonitorPad,
    NotStarted,
    Stalled,
    Ended,
    NoTimestamp,
    Unreadable,
}

impl Fallback {
    fn describe(self) -> &'static str {
        match self {
            Fallback::NoMonitorPad => "no monitor stream is connected",
            Fallback::NotStarted => "the monitor stream has not started yet",
            Fallback::Stalled => "the monitor stream has stalled",
            Fallback::Ended => "the monitor stream has ended",
            Fallback::NoTimestamp => "the face frame has no timestamp to align the monitor by",
            Fallback::Unreadable => {
                "the monitor frame cannot be read (its caps are missing or do not match it)"
            }
        }
    }
}

/// What the monitor track says about a face frame.
enum MonitorDecision {
    /// The monitor frame's light and running time.
    Known(Light, i64),
    Fallback(Fallback),
    /// Not enough monitor data yet: wait for more.
    Wait,
}

/// The latest monitor frame at or before the face frame.
struct Shown {
    /// Running time at which it was shown.
    at: i64,
    /// Running time until which it counts as on screen: its duration or
    /// `monitor-timeout` after `at`, whichever is longer.
    valid_until: i64,
    /// The frame, until a face frame needs its light; a frame that a newer one
    /// replaces before then is never decoded.
    frame: Option<gst::Buffer>,
    light: Option<Light>,
}

impl Shown {
    /// The frame's light, computed the first time a face frame needs it. None while
    /// the frame cannot be read; it is kept, in case its caps arrive.
    fn light(&mut self, info: Option<&gst_video::VideoInfo>) -> Option<Light> {
        if self.light.is_none()
            && let (Some(buffer), Some(info)) = (self.frame.as_ref(), info)
        {
            self.light = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer.as_ref(), info)
                .ok()
                .and_then(|f| frame_view(&f).map(|view| Light::from_frame(&view)));
            if self.light.is_some() {
                self.frame = None;
            }
        }
        self.light.clone()
    }
}

#[derive(Default)]
struct MonitorTrack {
    info: Option<gst_video::VideoInfo>,
    current: Option<Shown>,
    /// The fallback in force, if any; a warning is posted when one starts.
    fallback: Option<Fallback>,
}

#[derive(Debug, Default, Clone, Copy)]
struct Stats {
    frames: u64,
    relit: u64,
    passed_through: u64,
    skipped_absent: u64,
    skipped_same_light: u64,
    skipped_static: u64,
    qos_reused: u64,
    /// Seconds spent on face frames in all, and on the parts outside the network:
    /// reading the face region into the network's input (crop, colour conversion,
    /// resampling) and putting the lighting change back into the frame.
    processing_seconds: f64,
    crop_seconds: f64,
    paste_seconds: f64,
    /// Seconds spent turning monitor frames into lights.
    monitor_light_seconds: f64,
    known_source: u64,
    predicted_source: u64,
    fallbacks: u64,
    resets: u64,
    monitor_frames: u64,
    /// Monitor frames whose light was computed: the ones face frames used.
    monitor_decoded: u64,
    monitor_out: u64,
    monitor_dropped: u64,
}

struct State {
    relighter: Relighter,
    temporal: Temporal,
    target_generation: u64,
    face_info: Option<gst_video::VideoInfo>,
    last_face_rt: Option<gst::ClockTime>,
    /// The last frame the network ran on, whose lighting change a skipped frame reuses.
    last: Option<Processed>,
    /// A NaN warning was posted and no frame has been relit since.
    nan_warned: bool,
}

/// What a frame the network ran on leaves for the frames that reuse it.
struct Processed {
    /// The network's input and the averaged source light.
    image: Vec<f32>,
    average: Light,
    change: LightingChange,
    crop: Crop,
    predicted: Option<Light>,
}

/// What is known about a frame when its path is chosen.
#[derive(Clone, Copy)]
struct FrameInput<'a> {
    frame: &'a Frame<'a>,
    crop: Crop,
    /// The network's input.
    image: &'a [f32],
    source: &'a Source,
    /// Already past its deadline (QoS).
    late: bool,
}

/// The work a frame gets.
enum FramePath {
    /// Nobody is in the face region: pass through.
    Absent,
    /// The source light is the target light: pass through.
    SameLight,
    /// Apply the last frame's lighting change.
    Reuse(Reuse),
    /// Run the network, with this averaged source light (None: to be predicted).
    Full(Option<Light>),
}

enum Reuse {
    /// The face region and the source light barely changed.
    Static,
    /// The frame is already late (QoS).
    Late,
}

/// Mean absolute difference of two images of the same size.
fn mean_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f32>() / a.len() as f32
}

/// Items for `monitor_src`'s task, in order.
enum SideItem {
    Event(gst::Event),
    Buffer(gst::Buffer),
}

#[derive(Default)]
struct SideInner {
    items: VecDeque<SideItem>,
    flushing: bool,
    /// Stream-start, caps and segment have been queued.
    started: bool,
}

/// The queue between the aggregator's thread and `monitor_src`'s task.
#[derive(Default)]
struct SideQueue {
    inner: Mutex<SideInner>,
    cond: Condvar,
}

impl SideQueue {
    fn lock(&self) -> MutexGuard<'_, SideInner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Queues an item; returns false when a buffer had to be dropped to make room.
    fn push(&self, item: SideItem) -> bool {
        let mut q = self.lock();
        if q.flushing {
            return true;
        }
        let mut kept = true;
        if matches!(item, SideItem::Buffer(_)) {
            let buffers = q
                .items
                .iter()
                .filter(|i| matches!(i, SideItem::Buffer(_)))
                .count();
            if buffers >= MONITOR_QUEUE
                && let Some(pos) = q
                    .items
                    .iter()
                    .position(|i| matches!(i, SideItem::Buffer(_)))
            {
                q.items.remove(pos);
                kept = false;
            }
        }
        q.items.push_back(item);
        self.cond.notify_one();
        kept
    }

    fn pop(&self) -> Option<SideItem> {
        let mut q = self.lock();
        loop {
            if q.flushing {
                return None;
            }
            if let Some(i) = q.items.pop_front() {
                return Some(i);
            }
            q = self.cond.wait(q).unwrap_or_else(|p| p.into_inner());
        }
    }

    fn set_flushing(&self, flushing: bool) {
        let mut q = self.lock();
        q.flushing = flushing;
        if flushing {
            q.items.clear();
        }
        self.cond.notify_all();
    }

    fn reset(&self) {
        let mut q = self.lock();
        q.items.clear();
        q.started = false;
    }
}

pub struct LsydRelight {
    face_pad: gst_base::AggregatorPad,
    monitor_src: gst::Pad,
    monitor_pad: Mutex<Option<gst_base::AggregatorPad>>,
    side: Arc<SideQueue>,
    settings: Mutex<Settings>,
    state: Mutex<Option<State>>,
    /// Kept after stop, so the last run's figures stay readable; reset at start.
    stats: Mutex<Stats>,
    /// The engine's counts as of the last frame, likewise kept after stop.
    engine_counts: Mutex<engine::EngineCounts>,
    /// Downstream's earliest useful running time, from its QoS events.
    qos_earliest: Mutex<Option<gst::ClockTime>>,
    /// Whether upstream is live, from the latency query.
    live: std::sync::atomic::AtomicBool,
    /// A warning about upstream's caps was posted (once per run).
    caps_warned: std::sync::atomic::AtomicBool,
    monitor: Mutex<MonitorTrack>,
    face_stream_id: Mutex<Option<glib::GString>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Face video: the formats above, at least `MIN_FACE_SIZE` on each side.
fn video_caps() -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format_list(FORMATS)
        .width_range(MIN_FACE_SIZE..)
        .height_range(MIN_FACE_SIZE..)
        .build()
}

/// Monitor content: the same formats, any size.
fn monitor_caps() -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format_list(FORMATS)
        .build()
}

/// What a pad takes and how to give it that, for error messages.
fn caps_advice(pad: &str) -> String {
    let formats: Vec<&str> = FORMATS.iter().map(|f| f.to_str().as_str()).collect();
    let size = if pad == "sink" {
        format!(" of at least {MIN_FACE_SIZE}x{MIN_FACE_SIZE}")
    } else {
        String::new()
    };
    format!(
        "{pad} takes raw video in {}{size}; put videoconvert (and videoscale) in front of it",
        formats.join(", ")
    )
}

fn monitor_src_caps(fps: gst::Fraction) -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format(VideoFormat::Rgb)
        .width((LIGHT_COLS * MONITOR_SCALE) as i32)
        .height((LIGHT_ROWS * MONITOR_SCALE) as i32)
        .framerate(fps)
        .pixel_aspect_ratio(gst::Fraction::new(1, 1))
        .build()
}

fn pixel_format(f: VideoFormat) -> Option<PixelFormat> {
    Some(match f {
        VideoFormat::I420 => PixelFormat::I420,
        VideoFormat::Nv12 => PixelFormat::Nv12,
        VideoFormat::Y444 => PixelFormat::Y444,
        VideoFormat::Rgba => PixelFormat::Rgba,
        VideoFormat::Bgra => PixelFormat::Bgra,
        VideoFormat::Rgbx => PixelFormat::Rgbx,
        VideoFormat::Bgrx => PixelFormat::Bgrx,
        VideoFormat::Rgb => PixelFormat::Rgb,
        VideoFormat::Bgr => PixelFormat::Bgr,
        _ => return None,
    })
}

fn yuv_matrix(info: &gst_video::VideoInfo) -> YuvMatrix {
    let c = info.colorimetry();
    let (kr, kb) = match c.matrix() {
        gst_video::VideoColorMatrix::Bt709 => (0.2126, 0.0722),
        gst_video::VideoColorMatrix::Bt2020 => (0.2627, 0.0593),
        gst_video::VideoColorMatrix::Smpte240m => (0.212, 0.087),
        gst_video::VideoColorMatrix::Fcc => (0.30, 0.11),
        _ => (0.299, 0.114),
    };
    YuvMatrix {
        kr,
        kb,
        limited: c.range() != gst_video::VideoColorRange::Range0_255,
    }
}

fn frame_view<'a>(f: &'a gst_video::VideoFrameRef<&gst::BufferRef>) -> Option<Frame<'a>> {
    let format = pixel_format(f.format())?;
    let strides = f.plane_stride();
    let plane = |i: usize| -> Plane<'a> {
        let i = i.min(f.n_planes() as usize - 1);
        Plane {
            data: f.plane_data(i as u32).unwrap_or(&[]),
            stride: strides[i] as usize,
        }
    };
    Some(Frame {
        format,
        width: f.width() as usize,
        height: f.height() as usize,
        planes: [plane(0), plane(1), plane(2)],
        matrix: yuv_matrix(f.info()),
    })
}

fn with_frame_mut<R>(
    f: &mut gst_video::VideoFrameRef<&mut gst::BufferRef>,
    body: impl FnOnce(&mut FrameMut) -> R,
) -> Option<R> {
    let format = pixel_format(f.format())?;
    let (width, height) = (f.width() as usize, f.height() as usize);
    let matrix = yuv_matrix(f.info());
    let strides: Vec<usize> = f.plane_stride().iter().map(|&s| s as usize).collect();
    let n = f.n_planes() as usize;
    let mut planes: Vec<&mut [u8]> = f.planes_data_mut().into_iter().collect();
    planes.truncate(n);
    let mut it = planes.into_iter();
    let mut next = |i: usize| -> (&mut [u8], usize) {
        match it.next() {
            Some(p) => (p, strides[i]),
            None => (&mut [], 0),
        }
    };
    let p0 = next(0);
    let p1 = next(1);
    let p2 = next(2);
    let mut fm = FrameMut {
        format,
        width,
        height,
        planes: [p0, p1, p2],
        matrix,
    };
    Some(body(&mut fm))
}

/// The predicted light as an 8-bit RGB image, each cell a square of pixels.
fn monitor_image(light: &Light) -> Vec<u8> {
    let (w, h) = (LIGHT_COLS * MONITOR_SCALE, LIGHT_ROWS * MONITOR_SCALE);
    let n = LIGHT_ROWS * LIGHT_COLS;
    let encode = |v: f32| {
        let v = v.clamp(0.0, 1.0);
        let s = if v <= 0.003_130_8 {
            v * 12.92
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0).round() as u8
    };
    let mut out = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let cell = (y / MONITOR_SCALE) * LIGHT_COLS + x / MONITOR_SCALE;
            for c in 0..3 {
                out[(y * w + x) * 3 + c] = encode(light.0[c * n + cell]);
            }
        }
    }
    out
}

fn load_target(path: &std::path::Path) -> Result<Light, String> {
    let file = std::fs::File::open(path)
        .map_err(|e| format!("cannot open target image {}: {e}", path.display()))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder
        .read_info()
        .map_err(|e| format!("{} is not a PNG image: {e}", path.display()))?;
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("cannot decode {}: {e}", path.display()))?;
    let (w, h) = (info.width as usize, info.height as usize);
    let channels = match info.color_type {
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Indexed => {
            return Err(format!(
                "{}: palette images are not supported",
                path.display()
            ));
        }
    };
    let rgb: Vec<u8> = buf[..w * h * channels]
        .chunks_exact(channels)
        .flat_map(|p| {
            if channels >= 3 {
                [p[0], p[1], p[2]]
            } else {
                [p[0]; 3]
            }
        })
        .collect();
    Ok(Light::from_frame(&Frame::packed_rgb(&rgb, w, h)))
}

/// A buffer the aggregator made from a GAP event: no picture, only time.
fn is_gap(buffer: &gst::BufferRef) -> bool {
    buffer.flags().contains(gst::BufferFlags::GAP) && buffer.size() == 0
}

fn running_time(
    pad: &gst_base::AggregatorPad,
    pts: Option<gst::ClockTime>,
) -> Option<gst::ClockTime> {
    let segment = pad.segment();
    segment
        .downcast_ref::<gst::ClockTime>()?
        .to_running_time(pts?)
}

/// One frame's duration at the caps' frame rate, if it has one.
fn frame_duration(info: &gst_video::VideoInfo) -> Option<gst::ClockTime> {
    let fps = info.fps();
    (fps.numer() > 0).then(|| {
        gst::ClockTime::SECOND
            .mul_div_floor(fps.denom() as u64, fps.numer() as u64)
            .unwrap_or(gst::ClockTime::ZERO)
    })
}

impl LsydRelight {
    /// Decodes a new target image here, on the caller's thread, so that changing the
    /// target while playing never stalls a frame; the stream then only encodes it.
    fn set_target_location(&self, path: PathBuf) {
        let decoded = load_target(&path);
        let running = lock(&self.state).is_some();
        let mut s = lock(&self.settings);
        s.target_location = path;
        match decoded {
            Ok(light) => {
                s.target_light = Some(Arc::new(light));
                s.target_generation += 1;
            }
            // Stopped, the error surfaces when the element starts.
            Err(_) if !running => s.target_light = None,
            Err(e) => {
                drop(s);
                gst::element_imp_warning!(
                    self,
                    gst::ResourceError::OpenRead,
                    ("Keeping the previous target light: {}", e),
                    ["Set target-location to a readable PNG image of monitor content."]
                );
            }
        }
    }

    fn settings(&self) -> Settings {
        lock(&self.settings).clone()
    }

    fn monitor_pad(&self) -> Option<gst_base::AggregatorPad> {
        lock(&self.monitor_pad).clone()
    }

    /// Updates the statistics. The lock is held only for `update`, never while
    /// posting messages or running the network, so reading `stats` never waits long.
    fn count(&self, update: impl FnOnce(&mut Stats)) {
        update(&mut lock(&self.stats));
    }

    /// Forgets the face stream's temporal state: after flushes, seeks, discontinuities,
    /// caps changes and gaps. The monitor frame on screen stays: it is still on screen.
    fn reset_state(&self, why: &str) {
        if let Some(s) = lock(&self.state).as_mut() {
            // Only a reset that forgets something counts.
            if s.relighter.has_history() {
                self.count(|st| st.resets += 1);
            }
            s.relighter.reset();
            s.last_face_rt = None;
            s.last = None;
        }
        gst::debug!(CAT, imp = self, "reset temporal state: {why}");
    }

    /// Reads the monitor stream up to the face frame's time.
    fn consume_monitor(
        &self,
        pad: &gst_base::AggregatorPad,
        face_rt: Option<gst::ClockTime>,
        timeout: bool,
        s: &Settings,
    ) -> MonitorDecision {
        let target = face_rt.map(|t| t.nseconds() as i64 - s.monitor_offset);
        let mut track = lock(&self.monitor);
        enum End {
            Later,
            Ended,
            Deadline,
        }
        let end = loop {
            match pad.peek_buffer() {
                Some(buffer) if is_gap(&buffer) => {
                    // A gap in the screen capture shows nothing new.
                    pad.drop_buffer();
                }
                Some(buffer) => {
                    let rt = running_time(pad, buffer.pts()).map(|t| t.nseconds() as i64);
                    // Monitor frames without a timestamp are taken as shown now.
                    let shown_by_target = match (rt, target) {
                        (Some(rt), Some(target)) => rt <= target,
                        _ => true,
                    };
                    if !shown_by_target {
                        break End::Later;
                    }
                    let at = rt.or(target).unwrap_or(0);
                    let hold = buffer
                        .duration()
                        .unwrap_or(gst::ClockTime::ZERO)
                        .max(s.monitor_timeout);
                    track.current = Some(Shown {
                        at,
                        valid_until: at.saturating_add(hold.nseconds() as i64),
                        frame: Some(buffer),
                        light: None,
                    });
                    self.count(|st| st.monitor_frames += 1);
                    pad.drop_buffer();
                }
                None if pad.is_eos() => break End::Ended,
                None if timeout || target.is_none() => break End::Deadline,
                None => return MonitorDecision::Wait,
            }
        };
        let track = &mut *track;
        let info = track.info.as_ref();
        let known = |c: &mut Shown| {
            let decoding = c.light.is_none();
            let started = std::time::Instant::now();
            let light = c.light(info);
            if decoding && light.is_some() {
                self.count(|st| {
                    st.monitor_decoded += 1;
                    st.monitor_light_seconds += started.elapsed().as_secs_f64();
                });
            }
            match light {
                Some(l) => MonitorDecision::Known(l, c.at),
                None => MonitorDecision::Fallback(Fallback::Unreadable),
            }
        };
        let Some(target) = target else {
            return match track.current.as_mut() {
                Some(c) => known(c),
                None => MonitorDecision::Fallback(Fallback::NoTimestamp),
            };
        };
        // Decided by running times alone, so the outcome does not depend on how far
        // behind real time the element runs.
        match (track.current.as_mut(), end) {
            (Some(c), _) if target <= c.valid_until => known(c),
            (_, End::Ended) => MonitorDecision::Fallback(Fallback::Ended),
            (None, _) => MonitorDecision::Fallback(Fallback::NotStarted),
            (Some(_), _) => MonitorDecision::Fallback(Fallback::Stalled),
        }
    }

    /// Posts a warning when a fallback starts and a message when the monitor returns.
    fn note_fallback(&self, fallback: Option<Fallback>) {
        let mut track = lock(&self.monitor);
        if track.fallback == fallback {
            return;
        }
        let previous = std::mem::replace(&mut track.fallback, fallback);
        drop(track);
        match (previous, fallback) {
            (_, Some(f)) if f != Fallback::NoMonitorPad => {
                self.count(|st| st.fallbacks += 1);
                gst::element_imp_warning!(
                    self,
                    gst::StreamError::Failed,
                    (
                        "Relighting with the predicted source light: {}",
                        f.describe()
                    ),
                    [
                        "Connect or restart the monitor stream; relighting follows it again as soon as it returns."
                    ]
                );
            }
            (Some(_), None) => {
                gst::element_imp_info!(
                    self,
                    gst::StreamError::Failed,
                    ("The monitor stream is back: relighting with the monitor's light again")
                );
            }
            _ => {}
        }
    }

    /// Brings the temporal state and the target up to date for the next frame:
    /// resets after a break in the stream, new filter settings, a new target.
    fn update_state(&self, state: &mut State, buffer: &gst::Buffer, s: &Settings) {
        let rt = running_time(&self.face_pad, buffer.pts());
        // A slow stream (1 fps) is not a broken one: a gap counts only beyond a few frames.
        let frame = buffer
            .duration()
            .or_else(|| state.face_info.as_ref().and_then(frame_duration))
            .unwrap_or(gst::ClockTime::ZERO);
        let gap_limit = s.reset_gap.max(3 * frame);
        let gap = match (state.last_face_rt, rt) {
            (Some(a), Some(b)) => a.nseconds().abs_diff(b.nseconds()) > gap_limit.nseconds(),
            _ => false,
        };
        if (buffer.flags().contains(gst::BufferFlags::DISCONT) || gap)
            && state.relighter.has_history()
        {
            state.relighter.reset();
            state.last = None;
            self.count(|st| st.resets += 1);
            gst::debug!(CAT, imp = self, "reset temporal state at a discontinuity");
        }
        state.last_face_rt = rt.or(state.last_face_rt);
        if state.temporal != s.temporal {
            state.relighter.set_temporal(s.temporal);
            state.temporal = s.temporal;
            state.last = None;
        }
        if state.target_generation != s.target_generation
            && let Some(light) = &s.target_light
        {
            match state.relighter.set_target(light) {
                Ok(()) => gst::info!(
                    CAT,
                    imp = self,
                    "target light now {}",
                    s.target_location.display()
                ),
                Err(e) => gst::element_imp_warning!(
                    self,
                    gst::LibraryError::Failed,
                    (
                        "Keeping the previous target light: cannot encode the new one: {}",
                        e
                    )
                ),
            }
            state.target_generation = s.target_generation;
            state.last = None;
        }
    }

    /// Which work this frame needs.
    fn choose_path(
        &self,
        state: &mut State,
        f: &FrameInput,
        s: &Settings,
    ) -> Result<FramePath, gst::FlowError> {
        let FrameInput {
            frame,
            crop,
            image,
            source,
            late,
        } = *f;
        if s.skip_absent && state.relighter.has_presence() {
            let small = sample_crop(frame, crop, PRESENCE_SIZE);
            let p = state
                .relighter
                .presence(&small)
                .map_err(|e| self.engine_failed(e))?;
            if p.is_some_and(|p| p < s.presence_threshold as f32) {
                return Ok(FramePath::Absent);
            }
        }
        let average = state.relighter.peek_average(source);
        // Only a known source light can be compared: a predicted one comes from the
        // frame, so it must be predicted afresh each time.
        if s.skip_same_light
            && matches!(source, Source::Known(_))
            && let (Some(avg), Some(target)) = (&average, state.relighter.target())
            && avg.distance(target) <= s.same_light_tolerance as f32
        {
            return Ok(FramePath::SameLight);
        }
        if let Some(last) = &state.last
            && last.crop == crop
        {
            if late && s.qos {
                return Ok(FramePath::Reuse(Reuse::Late));
            }
            let light_change = match (&average, &last.average) {
                (Some(a), b) => a.distance(b),
                (None, _) => f32::INFINITY,
            };
            if s.skip_static
                && mean_abs_diff(image, &last.image) <= s.static_threshold as f32
                && light_change <= s.static_light_threshold as f32
            {
                return Ok(FramePath::Reuse(Reuse::Static));
            }
        }
        Ok(FramePath::Full(average))
    }

    /// In a live pipeline: is a frame of this running time already past its deadline,
    /// by the clock or by downstream's QoS?
    fn is_late(&self, rt: Option<gst::ClockTime>, duration: Option<gst::ClockTime>) -> bool {
        let Some(rt) = rt else { return false };
        let frame = duration.unwrap_or(gst::ClockTime::from_mseconds(33));
        if let Some(earliest) = *lock(&self.qos_earliest)
            && rt + frame < earliest
        {
            return true;
        }
        let obj = self.obj();
        let (Some(clock), Some(base)) = (obj.clock(), obj.base_time()) else {
            return false;
        };
        if !self.live.load(std::sync::atomic::Ordering::Relaxed) {
            return false;
        }
        let latency = obj.latency().unwrap_or(gst::ClockTime::ZERO);
        let now = clock.time().saturating_sub(base);
        now > rt + latency + frame
    }

    fn post_qos(&self, buffer: &gst::Buffer, rt: Option<gst::ClockTime>) {
        let stats = *lock(&self.stats);
        let segment = self.face_pad.segment();
        let stream_time = segment
            .downcast_ref::<gst::ClockTime>()
            .and_then(|s| s.to_stream_time(buffer.pts()?));
        let msg = gst::message::Qos::builder(true)
            .running_time(rt)
            .stream_time(stream_time)
            .timestamp(buffer.pts())
            .duration(buffer.duration())
            .stats(
                gst::format::Buffers::from_u64(stats.frames - stats.qos_reused),
                gst::format::Buffers::from_u64(stats.qos_reused),
            )
            .src(&*self.obj())
            .build();
        let _ = self.obj().post_message(msg);
    }

    fn engine_failed(&self, e: engine::EngineError) -> gst::FlowError {
        gst::element_imp_error!(self, gst::StreamError::Failed, ("Relighting failed: {}", e));
        gst::FlowError::Error
    }

    /// Relights one face buffer in place (a copy, when upstream still holds it).
    /// `late` says the frame is already behind its deadline (QoS).
    fn process_frame(
        &self,
        mut buffer: gst::Buffer,
        source: Source,
        late: bool,
        s: &Settings,
    ) -> Result<gst::Buffer, gst::FlowError> {
        let started = std::time::Instant::now();
        self.count(|st| {
            st.frames += 1;
            match &source {
                Source::Known(_) => st.known_source += 1,
                Source::Unknown => st.predicted_source += 1,
            }
        });
        let mut guard = lock(&self.state);
        let state = guard.as_mut().ok_or(gst::FlowError::Flushing)?;
        let info = state
            .face_info
            .clone()
            .ok_or(gst::FlowError::NotNegotiated)?;
        self.update_state(state, &buffer, s);

        let (w, h) = (info.width() as usize, info.height() as usize);
        let crop = Crop::centred(w, h, s.crop_x, s.crop_y, s.crop_size);
        let res = state.relighter.resolution();
        let (image, path) = {
            let frame = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer.as_ref(), &info)
                .map_err(|_| gst::FlowError::Error)?;
            let view = frame_view(&frame).ok_or(gst::FlowError::NotNegotiated)?;
            let cropping = std::time::Instant::now();
            let image = sample_crop(&view, crop, res);
            let crop_seconds = cropping.elapsed().as_secs_f64();
            self.count(|st| st.crop_seconds += crop_seconds);
            let input = FrameInput {
                frame: &view,
                crop,
                image: &image,
                source: &source,
                late,
            };
            let path = self.choose_path(state, &input, s)?;
            (image, path)
        };
        let want_prediction = self.monitor_src.is_linked();
        let feather = (s.feather * crop.size as f64).round() as usize;
        let apply =
            |buffer: &mut gst::Buffer, change: &LightingChange| -> Result<(), gst::FlowError> {
                let pasting = std::time::Instant::now();
                let mut frame =
                    gst_video::VideoFrameRef::from_buffer_ref_writable(buffer.make_mut(), &info)
                        .map_err(|_| gst::FlowError::Error)?;
                with_frame_mut(&mut frame, |fm| change.apply(fm, crop, feather));
                let paste_seconds = pasting.elapsed().as_secs_f64();
                self.count(|st| st.paste_seconds += paste_seconds);
                Ok(())
            };
        let mut warn_nan = false;
        let predicted = match path {
            FramePath::Absent => {
                // Nobody there: pass the frame through. The pose will have changed by
                // the time the person is back, so their temporal state must not carry over.
                self.count(|st| st.skipped_absent += 1);
                state.relighter.reset();
                state.last = None;
                None
            }
            FramePath::SameLight => {
                self.count(|st| st.skipped_same_light += 1);
                state.relighter.skip_frame(&source);
                state.last.as_ref().and_then(|l| l.predicted.clone())
            }
            FramePath::Reuse(why) => {
                self.count(|st| match why {
                    Reuse::Static => st.skipped_static += 1,
                    Reuse::Late => st.qos_reused += 1,
                });
                state.relighter.skip_frame(&source);
                let last = state.last.as_ref().expect("reuse needs a processed frame");
                apply(&mut buffer, &last.change)?;
                last.predicted.clone()
            }
            FramePath::Full(average) => {
                let out: FrameOutput = state
                    .relighter
                    .process(&image, source, want_prediction)
                    .map_err(|e| self.engine_failed(e))?;
                match out.relit {
                    Some(relit) => {
                        let format =
                            pixel_format(info.format()).ok_or(gst::FlowError::NotNegotiated)?;
                        let change =
                            LightingChange::new(&image, &relit, res, format, yuv_matrix(&info));
                        apply(&mut buffer, &change)?;
                        self.count(|st| st.relit += 1);
                        state.nan_warned = false;
                        state.last = Some(Processed {
                            image,
                            average: average.unwrap_or_else(|| out.source.clone()),
                            change,
                            crop,
                            predicted: out.predicted.clone(),
                        });
                    }
                    None => {
                        self.count(|st| st.passed_through += 1);
                        state.last = None;
                        warn_nan = !std::mem::replace(&mut state.nan_warned, true);
                    }
                }
                out.predicted
            }
        };
        *lock(&self.engine_counts) = state.relighter.counts();
        drop(guard);
        if warn_nan {
            gst::element_imp_warning!(
                self,
                gst::StreamError::Decode,
                ("The model produced NaN or Inf; passing frames through unchanged until it recovers"),
                ["The engine restarts its temporal state and relights the next frame afresh."]
            );
        }
        let processing_seconds = started.elapsed().as_secs_f64();
        self.count(|st| st.processing_seconds += processing_seconds);
        if want_prediction {
            self.push_monitor(
                predicted.as_ref(),
                buffer.pts(),
                buffer.duration(),
                info.fps(),
            );
        }
        Ok(buffer)
    }

    /// Queues stream-start, caps and segment for `monitor_src`, once per stream.
    fn start_side_stream(&self, fps: gst::Fraction) {
        if self.side.lock().started {
            return;
        }
        let id = lock(&self.face_stream_id)
            .clone()
            .map(|id| format!("{id}/monitor"))
            .unwrap_or_else(|| "lsydrelight/monitor".into());
        self.side
            .push(SideItem::Event(gst::event::StreamStart::new(&id)));
        self.side
            .push(SideItem::Event(gst::event::Caps::new(&monitor_src_caps(
                fps,
            ))));
        // Before the face stream's own segment (an empty stream), a time segment from 0.
        let segment = match self.face_pad.segment() {
            s if s.format() == gst::Format::Time => s,
            _ => gst::FormattedSegment::<gst::ClockTime>::new().upcast(),
        };
        self.side
            .push(SideItem::Event(gst::event::Segment::new(&segment)));
        self.side.lock().started = true;
    }

    /// Queues what `monitor_src` shows for a face frame: the predicted light, or a gap
    /// when there is none (nobody there, nothing to repeat, a broken prediction), so
    /// the side stream keeps time with the face stream and never stalls its sink.
    fn push_monitor(
        &self,
        light: Option<&Light>,
        pts: Option<gst::ClockTime>,
        duration: Option<gst::ClockTime>,
        fps: gst::Fraction,
    ) {
        self.start_side_stream(fps);
        let Some(light) = light else {
            if let Some(pts) = pts {
                self.side.push(SideItem::Event(
                    gst::event::Gap::builder(pts).duration(duration).build(),
                ));
            }
            return;
        };
        let mut buffer = gst::Buffer::from_mut_slice(monitor_image(light));
        {
            let b = buffer.get_mut().expect("new buffer");
            b.set_pts(pts);
            b.set_duration(duration);
        }
        let kept = self.side.push(SideItem::Buffer(buffer));
        self.count(|st| {
            st.monitor_out += 1;
            if !kept {
                st.monitor_dropped += 1;
            }
        });
    }

    fn monitor_src_activate(&self, pad: &gst::Pad, active: bool) -> Result<(), gst::LoggableError> {
        if active {
            self.side.set_flushing(false);
            let side = self.side.clone();
            let task_pad = pad.clone();
            pad.start_task(move || match side.pop() {
                Some(SideItem::Event(e)) => {
                    if e.type_() == gst::EventType::Eos {
                        let _ = task_pad.push_event(e);
                        let _ = task_pad.pause_task();
                    } else {
                        let _ = task_pad.push_event(e);
                    }
                }
                Some(SideItem::Buffer(b)) => {
                    if let Err(err) = task_pad.push(b) {
                        gst::debug!(CAT, obj = task_pad, "monitor_src push: {err:?}");
                    }
                }
                None => {
                    let _ = task_pad.pause_task();
                }
            })
            .map_err(|e| gst::loggable_error!(CAT, "cannot start the monitor_src task: {e}"))?;
        } else {
            self.side.set_flushing(true);
            pad.stop_task()
                .map_err(|e| gst::loggable_error!(CAT, "cannot stop the monitor_src task: {e}"))?;
            self.side.reset();
        }
        Ok(())
    }

    fn stats(&self) -> gst::Structure {
        let s = *lock(&self.stats);
        let c = *lock(&self.engine_counts);
        gst::Structure::builder("lsydrelight-stats")
            .field("frames", s.frames)
            .field("relit", s.relit)
            .field("passed-through", s.passed_through)
            .field("skipped-absent", s.skipped_absent)
            .field("skipped-same-light", s.skipped_same_light)
            .field("skipped-static", s.skipped_static)
            .field("qos-reused", s.qos_reused)
            .field("processing-seconds", s.processing_seconds)
            .field("network-seconds", c.network_seconds)
            .field("crop-seconds", s.crop_seconds)
            .field("paste-seconds", s.paste_seconds)
            .field("smoothing-seconds", c.filter_seconds)
            .field("monitor-light-seconds", s.monitor_light_seconds)
            .field("known-source", s.known_source)
            .field("predicted-source", s.predicted_source)
            .field("fallbacks", s.fallbacks)
            .field("resets", s.resets)
            .field("monitor-frames", s.monitor_frames)
            .field("monitor-decoded", s.monitor_decoded)
            .field("monitor-out", s.monitor_out)
            .field("monitor-dropped", s.monitor_dropped)
            .field("target-encodes", c.target_encodes)
            .field("light-predictions", c.predictions)
            .field("non-finite", c.non_finite)
            .build()
    }
}

#[glib::object_subclass]
impl ObjectSubclass for LsydRelight {
    const NAME: &'static str = "GstLsydRelight";
    type Type = super::LsydRelight;
    type ParentType = gst_base::Aggregator;

    fn with_class(klass: &Self::Class) -> Self {
        let face_pad = gst::PadBuilder::<gst_base::AggregatorPad>::from_template(
            &klass.pad_template("sink").unwrap(),
        )
        .name("sink")
        .build();
        let monitor_src =
            gst::Pad::builder_from_template(&klass.pad_template("monitor_src").unwrap())
                .name("monitor_src")
                .activatemode_function(|pad, parent, mode, active| {
                    LsydRelight::catch_panic_pad_function(
                        parent,
                        || {
                            Err(gst::loggable_error!(
                                CAT,
                                "panic while activating monitor_src"
                            ))
                        },
                        |imp| match mode {
                            gst::PadMode::Push => imp.monitor_src_activate(pad, active),
                            _ => Err(gst::loggable_error!(CAT, "monitor_src only pushes")),
                        },
                    )
                })
                .query_function(|pad, parent, query| {
                    LsydRelight::catch_panic_pad_function(
                        parent,
                        || false,
                        |imp| match query.view_mut() {
                            gst::QueryViewMut::Caps(q) => {
                                let fps = lock(&imp.state)
                                    .as_ref()
                                    .and_then(|s| s.face_info.as_ref().map(|i| i.fps()))
                                    .unwrap_or(gst::Fraction::new(0, 1));
                                let caps = if fps.numer() > 0 {
                                    monitor_src_caps(fps)
                                } else {
                                    pad.pad_template_caps()
                                };
                                let caps = match q.filter() {
                                    Some(f) => {
                                        f.intersect_with_mode(&caps, gst::CapsIntersectMode::First)
                                    }
                                    None => caps,
                                };
                                q.set_result(&caps);
                                true
                            }
                            _ => gst::Pad::query_default(pad, Some(&*imp.obj()), query),
                        },
                    )
                })
                .event_function(|_pad, _parent, event| {
                    // Upstream events on the side stream (QoS, navigation, reconfigure) have nowhere to go.
                    event.type_() == gst::EventType::Reconfigure
                })
                .build();
        Self {
            face_pad,
            monitor_src,
            monitor_pad: Mutex::new(None),
            side: Arc::new(SideQueue::default()),
            settings: Mutex::new(Settings::default()),
            state: Mutex::new(None),
            stats: Mutex::new(Stats::default()),
            engine_counts: Mutex::new(Default::default()),
            qos_earliest: Mutex::new(None),
            live: std::sync::atomic::AtomicBool::new(false),
            caps_warned: std::sync::atomic::AtomicBool::new(false),
            monitor: Mutex::new(MonitorTrack::default()),
            face_stream_id: Mutex::new(None),
        }
    }
}

impl ObjectImpl for LsydRelight {
    fn properties() -> &'static [glib::ParamSpec] {
        static PROPERTIES: LazyLock<Vec<glib::ParamSpec>> = LazyLock::new(|| {
            let d = Settings::default();
            vec![
                glib::ParamSpecString::builder("model-location")
                    .nick("Model")
                    .blurb("Folder of the personalised model (model.json and its ONNX stages); the shipped default is models/default")
                    .default_value(Some(d.model_location.to_str().unwrap_or("")))
                    .mutable_ready()
                    .build(),
                glib::ParamSpecString::builder("ort-library")
                    .nick("ONNX Runtime library")
                    .blurb("Path of libonnxruntime.so (1.31, from the onnxruntime Python wheel); LSYDRELIGHT_ORT_LIBRARY sets the default. One library per process")
                    .default_value(Some(d.ort_library.to_str().unwrap_or("")))
                    .mutable_ready()
                    .build(),
                glib::ParamSpecEnum::builder_with_default("execution-provider", d.provider)
                    .nick("Execution provider")
                    .blurb("Where the network runs; a provider that cannot start is an error, never a silent fall back to the CPU")
                    .mutable_ready()
                    .build(),
                glib::ParamSpecUInt::builder("threads")
                    .nick("Threads")
                    .blurb("CPU threads of each network stage (the small presence check always runs on one CPU thread)")
                    .minimum(1)
                    .maximum(64)
                    .default_value(DEFAULT_THREADS)
                    .mutable_ready()
                    .build(),
                glib::ParamSpecString::builder("target-location")
                    .nick("Target light")
                    .blurb("PNG image of the monitor content to relight to (as a screen capture would show it); can change while playing")
                    .default_value(Some(d.target_location.to_str().unwrap_or("")))
                    .mutable_playing()
                    .build(),
                glib::ParamSpecInt64::builder("monitor-offset")
                    .nick("Monitor offset")
                    .blurb("Nanoseconds by which the monitor content that lit a face frame precedes it (display and camera latency); a negative offset, for a screen capture that lags, adds as much latency")
                    .minimum(-MAX_MONITOR_OFFSET)
                    .maximum(MAX_MONITOR_OFFSET)
                    .default_value(DEFAULT_MONITOR_OFFSET)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecUInt64::builder("monitor-timeout")
                    .nick("Monitor timeout")
                    .blurb("Nanoseconds a monitor frame stays on screen without a newer one (or its duration, if longer); after that the monitor stream counts as stalled and the predicted light is used")
                    .default_value(DEFAULT_MONITOR_TIMEOUT.nseconds())
                    .mutable_playing()
                    .build(),
                glib::ParamSpecFloat::builder("alpha")
                    .nick("Feature smoothing")
                    .blurb("Weight of the current frame's de-lit features, f = alpha*f_t + (1-alpha)*f_(t-1); 1 turns smoothing off (paper: 0.7)")
                    .minimum(0.0)
                    .maximum(1.0)
                    .default_value(d.temporal.alpha)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecFloat::builder("beta")
                    .nick("Source-light averaging decay")
                    .blurb("Weight beta^i of the source light i frames ago in the average (paper: 0.6)")
                    .minimum(0.0)
                    .maximum(1.0)
                    .default_value(d.temporal.beta)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecUInt::builder("average-frames")
                    .nick("Source-light averaging frames")
                    .blurb("Number N of frames whose source lights are averaged; 1 turns averaging off (paper: 3)")
                    .minimum(1)
                    .maximum(16)
                    .default_value(d.temporal.average_frames as u32)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecDouble::builder("crop-x")
                    .nick("Face region centre x")
                    .blurb("Horizontal centre of the square face region, as a fraction of the frame width")
                    .minimum(0.0)
                    .maximum(1.0)
                    .default_value(DEFAULT_CROP_CENTRE)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecDouble::builder("crop-y")
                    .nick("Face region centre y")
                    .blurb("Vertical centre of the square face region, as a fraction of the frame height")
                    .minimum(0.0)
                    .maximum(1.0)
                    .default_value(DEFAULT_CROP_CENTRE)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecDouble::builder("crop-size")
                    .nick("Face region size")
                    .blurb("Side of the square face region as a fraction of the frame's shorter side (1: a head-and-shoulders square of full height)")
                    .minimum(0.05)
                    .maximum(1.0)
                    .default_value(DEFAULT_CROP_SIZE)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecDouble::builder("feather")
                    .nick("Feather")
                    .blurb("Width, as a fraction of the face region, over which the relighting fades out towards region edges inside the frame")
                    .minimum(0.0)
                    .maximum(0.5)
                    .default_value(DEFAULT_FEATHER)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecUInt64::builder("reset-gap")
                    .nick("Reset gap")
                    .blurb("Nanoseconds between face frames beyond which the temporal state starts afresh")
                    .default_value(DEFAULT_RESET_GAP.nseconds())
                    .mutable_playing()
                    .build(),
                glib::ParamSpecBoolean::builder("skip-static")
                    .nick("Skip static scenes")
                    .blurb("Reuse the last relighting while the face region and the source light barely change (thresholds below); for clean, still sources such as screen recordings, off by default because webcam noise never passes the thresholds")
                    .default_value(DEFAULT_SKIP_STATIC)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecDouble::builder("static-threshold")
                    .nick("Static image threshold")
                    .blurb("Mean absolute change of the network's input (sRGB in [0, 1]) since the last relit frame below which the scene counts as static")
                    .minimum(0.0)
                    .maximum(1.0)
                    .default_value(DEFAULT_STATIC_THRESHOLD)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecDouble::builder("static-light-threshold")
                    .nick("Static light threshold")
                    .blurb("Mean absolute change of the averaged source light (linear) below which the light counts as unchanged")
                    .minimum(0.0)
                    .maximum(1.0)
                    .default_value(DEFAULT_STATIC_LIGHT_THRESHOLD)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecBoolean::builder("skip-same-light")
                    .nick("Skip when source is target")
                    .blurb("Pass frames through when the source light equals the target light within same-light-tolerance")
                    .default_value(DEFAULT_SKIP_SAME_LIGHT)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecDouble::builder("same-light-tolerance")
                    .nick("Same light tolerance")
                    .blurb("Mean absolute difference of source and target light (linear) under which they count as the same")
                    .minimum(0.0)
                    .maximum(1.0)
                    .default_value(DEFAULT_SAME_LIGHT_TOLERANCE)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecBoolean::builder("skip-absent")
                    .nick("Skip when nobody is there")
                    .blurb("Pass frames through untouched while the model's presence stage sees nobody in the face region (the user walked away)")
                    .default_value(DEFAULT_SKIP_ABSENT)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecDouble::builder("presence-threshold")
                    .nick("Presence threshold")
                    .blurb("Probability of someone being in the face region below which nobody counts as there")
                    .minimum(0.0)
                    .maximum(1.0)
                    .default_value(DEFAULT_PRESENCE_THRESHOLD)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecBoolean::builder("qos")
                    .nick("QoS")
                    .blurb("In live pipelines, reuse the last relighting for frames that are already late instead of falling further behind, and post QoS messages")
                    .default_value(DEFAULT_QOS)
                    .mutable_playing()
                    .build(),
                glib::ParamSpecBoxed::builder::<gst::Structure>("stats")
                    .nick("Statistics")
                    .blurb("Frames processed, relit, passed through and skipped (and why), source lights used, monitor fallbacks, resets, work done, and seconds spent: in all, in the network, cropping, pasting, smoothing and reading monitor frames")
                    .read_only()
                    .build(),
            ]
        });
        PROPERTIES.as_ref()
    }

    fn set_property(&self, _id: usize, value: &glib::Value, pspec: &glib::ParamSpec) {
        let path = |v: &glib::Value| {
            PathBuf::from(v.get::<Option<String>>().ok().flatten().unwrap_or_default())
        };
        match pspec.name() {
            "target-location" => return self.set_target_location(path(value)),
            "monitor-offset" => {
                let offset: i64 = value.get().expect("type checked");
                lock(&self.settings).monitor_offset = offset;
                // A negative offset means waiting for monitor frames after the face frame.
                self.obj()
                    .set_latency(gst::ClockTime::from_nseconds((-offset).max(0) as u64), None);
                return;
            }
            _ => {}
        }
        let mut s = lock(&self.settings);
        match pspec.name() {
            "model-location" => s.model_location = path(value),
            "ort-library" => s.ort_library = path(value),
            "execution-provider" => s.provider = value.get().expect("type checked"),
            "threads" => s.threads = value.get().expect("type checked"),
            "monitor-timeout" => {
                s.monitor_timeout =
                    gst::ClockTime::from_nseconds(value.get().expect("type checked"))
            }
            "alpha" => s.temporal.alpha = value.get().expect("type checked"),
            "beta" => s.temporal.beta = value.get().expect("type checked"),
            "average-frames" => {
                s.temporal.average_frames = value.get::<u32>().expect("type checked") as usize
            }
            "crop-x" => s.crop_x = value.get().expect("type checked"),
            "crop-y" => s.crop_y = value.get().expect("type checked"),
            "crop-size" => s.crop_size = value.get().expect("type checked"),
            "feather" => s.feather = value.get().expect("type checked"),
            "reset-gap" => {
                s.reset_gap = gst::ClockTime::from_nseconds(value.get().expect("type checked"))
            }
            "skip-static" => s.skip_static = value.get().expect("type checked"),
            "static-threshold" => s.static_threshold = value.get().expect("type checked"),
            "static-light-threshold" => {
                s.static_light_threshold = value.get().expect("type checked")
            }
            "skip-same-light" => s.skip_same_light = value.get().expect("type checked"),
            "same-light-tolerance" => s.same_light_tolerance = value.get().expect("type checked"),
            "skip-absent" => s.skip_absent = value.get().expect("type checked"),
            "presence-threshold" => s.presence_threshold = value.get().expect("type checked"),
            "qos" => s.qos = value.get().expect("type checked"),
            other => unreachable!("unknown property {other}"),
        }
    }

    fn property(&self, _id: usize, pspec: &glib::ParamSpec) -> glib::Value {
        let s = lock(&self.settings);
        let text = |p: &PathBuf| p.to_string_lossy().into_owned().to_value();
        match pspec.name() {
            "model-location" => text(&s.model_location),
            "ort-library" => text(&s.ort_library),
            "execution-provider" => s.provider.to_value(),
            "threads" => s.threads.to_value(),
            "target-location" => text(&s.target_location),
            "monitor-offset" => s.monitor_offset.to_value(),
            "monitor-timeout" => s.monitor_timeout.nseconds().to_value(),
            "alpha" => s.temporal.alpha.to_value(),
            "beta" => s.temporal.beta.to_value(),
            "average-frames" => (s.temporal.average_frames as u32).to_value(),
            "crop-x" => s.crop_x.to_value(),
            "crop-y" => s.crop_y.to_value(),
            "crop-size" => s.crop_size.to_value(),
            "feather" => s.feather.to_value(),
            "reset-gap" => s.reset_gap.nseconds().to_value(),
            "skip-static" => s.skip_static.to_value(),
            "static-threshold" => s.static_threshold.to_value(),
            "static-light-threshold" => s.static_light_threshold.to_value(),
            "skip-same-light" => s.skip_same_light.to_value(),
            "same-light-tolerance" => s.same_light_tolerance.to_value(),
            "skip-absent" => s.skip_absent.to_value(),
            "presence-threshold" => s.presence_threshold.to_value(),
            "qos" => s.qos.to_value(),
            "stats" => {
                drop(s);
                self.stats().to_value()
            }
            other => unreachable!("unknown property {other}"),
        }
    }

    fn constructed(&self) {
        self.parent_constructed();
        let obj = self.obj();
        obj.add_pad(&self.face_pad).expect("add sink pad");
        obj.add_pad(&self.monitor_src).expect("add monitor_src pad");
    }
}

impl GstObjectImpl for LsydRelight {}

impl ElementImpl for LsydRelight {
    fn metadata() -> Option<&'static gst::subclass::ElementMetadata> {
        static META: LazyLock<gst::subclass::ElementMetadata> = LazyLock::new(|| {
            gst::subclass::ElementMetadata::new(
                "Personalised face relighting",
                "Filter/Effect/Video",
                "Relights the face in a video to a target monitor light with a network personalised to the person, \
                 aligned with what their monitor showed (Choi, Christman, Sengupta, ECCV 2024)",
                "lsydrelight developers",
            )
        });
        Some(&*META)
    }

    fn pad_templates() -> &'static [gst::PadTemplate] {
        static TEMPLATES: LazyLock<Vec<gst::PadTemplate>> = LazyLock::new(|| {
            let caps = video_caps();
            let agg = gst_base::AggregatorPad::static_type();
            vec![
                gst::PadTemplate::with_gtype(
                    "sink",
                    gst::PadDirection::Sink,
                    gst::PadPresence::Always,
                    &caps,
                    agg,
                )
                .expect("sink template"),
                gst::PadTemplate::with_gtype(
                    "monitor_sink",
                    gst::PadDirection::Sink,
                    gst::PadPresence::Request,
                    &monitor_caps(),
                    agg,
                )
                .expect("monitor_sink template"),
                gst::PadTemplate::with_gtype(
                    "src",
                    gst::PadDirection::Src,
                    gst::PadPresence::Always,
                    &caps,
                    agg,
                )
                .expect("src template"),
                gst::PadTemplate::new(
                    "monitor_src",
                    gst::PadDirection::Src,
                    gst::PadPresence::Always,
                    &monitor_src_caps(gst::Fraction::new(0, 1))
                        .into_iter()
                        .map(|(s, _)| {
                            let mut s = s.to_owned();
                            s.remove_field("framerate");
                            s.set(
                                "framerate",
                                gst::FractionRange::new(
                                    gst::Fraction::new(0, 1),
                                    gst::Fraction::new(i32::MAX, 1),
                                ),
                            );
                            s
                        })
                        .collect::<gst::Caps>(),
                )
                .expect("monitor_src template"),
            ]
        });
        TEMPLATES.as_ref()
    }

    fn release_pad(&self, pad: &gst::Pad) {
        let mut mp = lock(&self.monitor_pad);
        if mp
            .as_ref()
            .is_some_and(|p| p.upcast_ref::<gst::Pad>() == pad)
        {
            *mp = None;
            drop(mp);
            *lock(&self.monitor) = MonitorTrack::default();
        } else {
            drop(mp);
        }
        self.parent_release_pad(pad);
    }
}

impl AggregatorImpl for LsydRelight {
    fn start(&self) -> Result<(), gst::ErrorMessage> {
        let s = self.settings();
        let env = engine::environment(&s.ort_library)
            .map_err(|e| gst::error_msg!(gst::LibraryError::Init, ["{}", e]))?;
        let provider = match s.provider {
            ExecutionProvider::Cpu => Provider::Cpu,
            ExecutionProvider::Cuda => Provider::Cuda,
        };
        let mut relighter = Relighter::new(
            env,
            &s.model_location,
            s.threads as usize,
            provider,
            s.temporal,
        )
        .map_err(|e| match e {
            engine::EngineError::Provider(_) => gst::error_msg!(gst::LibraryError::Init, ["{}", e]),
            engine::EngineError::Model(engine::ContractError::Missing(_)) => {
                gst::error_msg!(gst::ResourceError::NotFound, ["{}", e])
            }
            _ => gst::error_msg!(gst::ResourceError::OpenRead, ["{}", e]),
        })?;
        let target = match &s.target_light {
            Some(light) => Light::clone(light),
            None => load_target(&s.target_location).map_err(|e| {
                gst::error_msg!(
                    gst::ResourceError::NotFound,
                    ["{}; set target-location to a PNG image of monitor content (shipped ones are in models/targets)", e]
                )
            })?,
        };
        relighter.set_target(&target).map_err(|e| {
            gst::error_msg!(
                gst::LibraryError::Failed,
                ["cannot encode the target light: {}", e]
            )
        })?;
        gst::info!(
            CAT,
            imp = self,
            "loaded model {} ({}x{}) with ONNX Runtime {}",
            relighter.manifest().name,
            relighter.resolution(),
            relighter.resolution(),
            s.ort_library.display()
        );
        *lock(&self.state) = Some(State {
            relighter,
            temporal: s.temporal,
            target_generation: s.target_generation,
            face_info: None,
            last_face_rt: None,
            last: None,
            nan_warned: false,
        });
        *lock(&self.stats) = Stats::default();
        *lock(&self.engine_counts) = Default::default();
        // Keep the monitor pad's caps: they may have arrived before start.
        let mut track = lock(&self.monitor);
        *track = MonitorTrack {
            info: track.info.take(),
            ..MonitorTrack::default()
        };
        Ok(())
    }

    fn stop(&self) -> Result<(), gst::ErrorMessage> {
        *lock(&self.qos_earliest) = None;
        self.caps_warned
            .store(false, std::sync::atomic::Ordering::Relaxed);
        *lock(&self.state) = None;
        *lock(&self.monitor) = MonitorTrack::default();
        self.side.reset();
        Ok(())
    }

    fn create_new_pad(
        &self,
        templ: &gst::PadTemplate,
        _req_name: Option<&str>,
        _caps: Option<&gst::Caps>,
    ) -> Option<gst_base::AggregatorPad> {
        if templ.name_template() != "monitor_sink" {
            return None;
        }
        let mut mp = lock(&self.monitor_pad);
        if mp.is_some() {
            gst::warning!(CAT, imp = self, "only one monitor_sink pad");
            return None;
        }
        let pad = gst::PadBuilder::<gst_base::AggregatorPad>::from_template(templ)
            .name("monitor_sink")
            .build();
        *mp = Some(pad.clone());
        Some(pad)
    }

    fn sink_event(&self, pad: &gst_base::AggregatorPad, event: gst::Event) -> bool {
        use gst::EventView;
        let is_face = pad == &self.face_pad;
        match event.view() {
            EventView::StreamStart(e) if is_face => {
                *lock(&self.face_stream_id) = Some(e.stream_id().into());
                self.reset_state("new stream");
            }
            EventView::Caps(c) => {
                let info = match gst_video::VideoInfo::from_caps(c.caps()) {
                    Ok(i) => i,
                    Err(_) => {
                        gst::element_imp_error!(
                            self,
                            gst::StreamError::Format,
                            ("Cannot read the caps {}", c.caps()),
                            ["{}", caps_advice(pad.name().as_str())]
                        );
                        return false;
                    }
                };
                if is_face {
                    let changed = lock(&self.state).as_mut().is_some_and(|s| {
                        let changed = s.face_info.as_ref() != Some(&info);
                        s.face_info = Some(info.clone());
                        changed
                    });
                    if changed {
                        self.reset_state("caps changed");
                        if self.side.lock().started {
                            self.side.push(SideItem::Event(gst::event::Caps::new(
                                &monitor_src_caps(info.fps()),
                            )));
                        }
                        self.obj().src_pad().mark_reconfigure();
                    }
                } else {
                    lock(&self.monitor).info = Some(info);
                }
            }
            EventView::Segment(e) if is_face => {
                let segment = e.segment().clone();
                if let Some(seg) = segment.downcast_ref::<gst::ClockTime>() {
                    self.obj().update_segment(seg);
                }
                if self.side.lock().started {
                    self.side
                        .push(SideItem::Event(gst::event::Segment::new(&segment)));
                }
                self.reset_state("new segment");
            }
            EventView::FlushStart(_) if is_face => {
                self.side.set_flushing(true);
                let _ = self.monitor_src.push_event(gst::event::FlushStart::new());
            }
            EventView::FlushStop(_) if is_face => {
                // The task pauses itself when it sees the flush; holding its stream lock
                // waits for that iteration to end, so the pause cannot land after the
                // restart below, and no buffer from before the flush follows it.
                self.side.set_flushing(true);
                let _task = self.monitor_src.stream_lock();
                let _ = self
                    .monitor_src
                    .push_event(gst::event::FlushStop::new(true));
                self.side.reset();
                if self.monitor_src.is_active() {
                    let _ = self.monitor_src_activate(&self.monitor_src, true);
                }
                *lock(&self.qos_earliest) = None;
                self.reset_state("flush");
            }
            EventView::FlushStop(_) => {
                lock(&self.monitor).current = None;
            }
            _ => {}
        }
        self.parent_sink_event(pad, event)
    }

    fn sink_query(&self, pad: &gst_base::AggregatorPad, query: &mut gst::QueryRef) -> bool {
        let is_face = pad == &self.face_pad;
        let templ = if is_face {
            video_caps()
        } else {
            monitor_caps()
        };
        match query.view_mut() {
            // The face and relit video have the same caps: ask downstream.
            gst::QueryViewMut::Caps(q) if is_face => {
                let downstream = self.obj().src_pad().peer_query_caps(Some(&templ));
                if let Some(f) = q.filter()
                    && !f.can_intersect(&templ)
                    && !self
                        .caps_warned
                        .swap(true, std::sync::atomic::Ordering::Relaxed)
                {
                    // Upstream can only offer what this pad cannot take: negotiation
                    // will fail upstream with a bare "not-negotiated"; say why here.
                    gst::element_imp_warning!(
                        self,
                        gst::StreamError::Format,
                        ("Upstream offers only video the face pad cannot take: {}", f),
                        ["{}", caps_advice("sink")]
                    );
                }
                let caps = match q.filter() {
                    Some(f) => f.intersect_with_mode(&downstream, gst::CapsIntersectMode::First),
                    None => downstream,
                };
                q.set_result(&caps);
                true
            }
            gst::QueryViewMut::AcceptCaps(q) => {
                let caps = q.caps().to_owned();
                let ok = if !caps.can_intersect(&templ) {
                    if caps.is_fixed() {
                        gst::element_imp_error!(
                            self,
                            gst::StreamError::Format,
                            ("{} cannot take {}", pad.name(), caps),
                            ["{}", caps_advice(pad.name().as_str())]
                        );
                    }
                    false
                } else {
                    !is_face || self.obj().src_pad().peer_query_accept_caps(&caps)
                };
                q.set_result(ok);
                true
            }
            _ => self.parent_sink_query(pad, query),
        }
    }

    fn src_query(&self, query: &mut gst::QueryRef) -> bool {
        let handled = self.parent_src_query(query);
        if handled && let gst::QueryView::Latency(q) = query.view() {
            self.live
                .store(q.result().0, std::sync::atomic::Ordering::Relaxed);
        }
        handled
    }

    fn src_event(&self, event: gst::Event) -> bool {
        if let gst::EventView::Qos(q) = event.view() {
            // As the base classes do: skip what downstream will only drop.
            let (_, _, diff, timestamp) = q.get();
            *lock(&self.qos_earliest) = timestamp.map(|t| {
                let late = if diff > 0 { 2 * diff } else { diff };
                gst::ClockTime::from_nseconds((t.nseconds() as i64 + late).max(0) as u64)
            });
        }
        self.parent_src_event(event)
    }

    fn update_src_caps(&self, _caps: &gst::Caps) -> Result<gst::Caps, gst::FlowError> {
        self.face_pad
            .current_caps()
            .ok_or(gst_base::AGGREGATOR_FLOW_NEED_DATA)
    }

    fn next_time(&self) -> Option<gst::ClockTime> {
        let buffer = self.face_pad.peek_buffer()?;
        running_time(&self.face_pad, buffer.pts())
    }

    fn aggregate(&self, timeout: bool) -> Result<gst::FlowSuccess, gst::FlowError> {
        let Some(face) = self.face_pad.peek_buffer() else {
            if self.face_pad.is_eos() {
                // The side stream ends too, even if it never showed anything.
                let fps = lock(&self.state)
                    .as_ref()
                    .and_then(|s| s.face_info.as_ref().map(|i| i.fps()))
                    .unwrap_or(gst::Fraction::new(0, 1));
                self.start_side_stream(fps);
                self.side.push(SideItem::Event(gst::event::Eos::new()));
                return Err(gst::FlowError::Eos);
            }
            return Err(gst_base::AGGREGATOR_FLOW_NEED_DATA);
        };
        if is_gap(&face) {
            // Nothing to relight: the gap goes on downstream, as a gap, and to
            // monitor_src too. Before the first frame (or after a flush) downstream has
            // no segment yet, and a gap may not precede it: that gap is dropped.
            self.face_pad.drop_buffer();
            let src = self.obj().src_pad().clone();
            if let Some(pts) = face.pts()
                && src.sticky_event::<gst::event::Segment>(0).is_some()
            {
                src.push_event(
                    gst::event::Gap::builder(pts)
                        .duration(face.duration())
                        .build(),
                );
                if self.monitor_src.is_linked() && self.side.lock().started {
                    self.side.push(SideItem::Event(
                        gst::event::Gap::builder(pts)
                            .duration(face.duration())
                            .build(),
                    ));
                }
            }
            return Ok(gst::FlowSuccess::Ok);
        }
        let s = self.settings();
        let face_rt = running_time(&self.face_pad, face.pts());
        let decision = match self.monitor_pad() {
            Some(pad) => self.consume_monitor(&pad, face_rt, timeout, &s),
            None => MonitorDecision::Fallback(Fallback::NoMonitorPad),
        };
        let (source, monitor_rt) = match decision {
            MonitorDecision::Wait => return Err(gst_base::AGGREGATOR_FLOW_NEED_DATA),
            MonitorDecision::Known(l, rt) => {
                self.note_fallback(None);
                (Source::Known(l), Some(rt))
            }
            MonitorDecision::Fallback(f) => {
                self.note_fallback(Some(f));
                (Source::Unknown, None)
            }
        };
        let buffer = self
            .face_pad
            .pop_buffer()
            .ok_or(gst_base::AGGREGATOR_FLOW_NEED_DATA)?;
        let late = s.qos && self.is_late(face_rt, buffer.duration());
        let mut out = self.process_frame(buffer, source, late, &s)?;
        if late {
            self.post_qos(&out, face_rt);
        }
        if let Some(rt) = monitor_rt {
            // Tells downstream which monitor frame lit this one, by its running time.
            gst::ReferenceTimestampMeta::add(
                out.make_mut(),
                &MONITOR_TIMESTAMP_CAPS,
                gst::ClockTime::from_nseconds(rt.max(0) as u64),
                gst::ClockTime::NONE,
            );
        }
        gst::trace!(CAT, imp = self, "relit frame at {:?}", out.pts());
        self.obj().finish_buffer(out)
    }
}
