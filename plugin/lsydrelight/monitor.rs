//! The monitor stream and its alignment rule.
//!
//! Each face frame uses the monitor frame shown at its running time minus
//! `monitor-offset`: the last monitor frame at or before that time, while it is
//! still on screen (its duration or `monitor-timeout`, whichever is longer).
//! Monitor frames a newer one replaces before a face frame needs them are never
//! decoded. Without usable monitor content (no pad, not yet started, stalled,
//! ended, unreadable) the face frame is relit with the predicted light, and a
//! warning says so once, when that starts.
//!
//! A monitor frame's light is computed on the monitor stream's own thread as the
//! frame arrives ([`ArrivalLights`]), so that the face frame does not wait for it,
//! while the monitor stream runs no faster than the face stream. Faster, most of
//! its frames are replaced before any face frame uses them, and only the ones
//! used get their light, on the element's thread.

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use gst::prelude::*;
use gst_base::prelude::*;

use crate::light::Light;

use super::lock;
use super::video::{frame_view, is_gap, running_time};

/// Lights computed as frames arrive and not yet taken, at most. The aggregator
/// queues a pad's frames up to its latency (one frame in a non-live pipeline);
/// beyond this many, further frames get their light when a face frame uses them.
const MAX_ARRIVED: usize = 32;

/// Monitor frames consumed per face frame (a running mean) above which lights
/// are no longer computed as frames arrive: most of them would go unused.
const MAX_EAGER_RATIO: f64 = 1.25;

/// Weight of the newest face frame in that running mean.
const RATIO_WEIGHT: f64 = 0.1;

/// Why a frame is relit with the predicted source light.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fallback {
    NoMonitorPad,
    NotStarted,
    Stalled,
    Ended,
    NoTimestamp,
    Unreadable,
}

impl Fallback {
    pub fn describe(self) -> &'static str {
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

/// What the monitor stream says about a face frame.
pub enum Decision {
    /// The monitor frame's light and the running time it was shown at.
    Known(Light, i64),
    Fallback(Fallback),
    /// Not enough monitor data yet: wait for more.
    Wait,
}

/// A change of fallback that the user hears about.
pub enum Transition {
    /// Relighting with the predicted light starts, for this reason.
    FallbackStarted(Fallback),
    /// The monitor's light is back.
    Returned,
}

/// The latest monitor frame at or before the face frame.
struct Shown {
    /// Running time at which it was shown.
    at: i64,
    /// Running time until which it counts as on screen.
    valid_until: i64,
    /// The frame, until a face frame needs its light.
    frame: Option<gst::Buffer>,
    light: Option<Light>,
}

/// Work done reading the monitor stream for one face frame, for statistics.
#[derive(Default)]
pub struct Reading {
    /// Monitor frames consumed.
    pub frames: u64,
    /// Whether a monitor frame's light was computed on this thread, and how long it took.
    pub decoded: Option<Duration>,
    /// Lights computed on the monitor stream's thread as frames arrived since the
    /// last reading (used or not), and the time they took there.
    pub arrival_decoded: u64,
    pub arrival_time: Duration,
}

/// A light computed as its frame arrived.
struct Arrived {
    /// The frame it came from: its buffer's address and timestamp, while the
    /// aggregator holds it.
    buffer: usize,
    pts: gst::ClockTime,
    light: Light,
}

/// What the monitor pad's probe shares with the track: the frames' lights,
/// computed on the monitor stream's thread before the aggregator queues them.
#[derive(Default)]
pub struct ArrivalLights {
    queue: Mutex<ArrivalQueue>,
    /// Set while the monitor stream runs faster than the face stream.
    lazy: AtomicBool,
}

#[derive(Default)]
struct ArrivalQueue {
    /// The stream's caps as the probe saw them, in order with its frames (the
    /// element's own `sink_event` sees them later, when the aggregator gets to them).
    info: Option<gst_video::VideoInfo>,
    lights: VecDeque<Arrived>,
    /// Lights computed and the time they took, since the track last read them.
    computed: u64,
    time: Duration,
}

impl ArrivalLights {
    /// Computes the lights of `pad`'s frames as they arrive, from now on.
    pub fn attach(pad: &gst_base::AggregatorPad) -> Arc<ArrivalLights> {
        let lights = Arc::new(ArrivalLights::default());
        let probe = lights.clone();
        pad.add_probe(
            gst::PadProbeType::BUFFER
                | gst::PadProbeType::EVENT_DOWNSTREAM
                | gst::PadProbeType::EVENT_FLUSH,
            move |_, info| {
                // A panic must not cross into GStreamer; the frame's light is then
                // computed when a face frame uses it, which reports what is wrong.
                let _ = catch_unwind(AssertUnwindSafe(|| match &info.data {
                    Some(gst::PadProbeData::Buffer(buffer)) => probe.arrive(buffer),
                    Some(gst::PadProbeData::Event(event)) => probe.event(event),
                    _ => {}
                }));
                gst::PadProbeReturn::Ok
            },
        );
        lights
    }

    fn arrive(&self, buffer: &gst::Buffer) {
        if self.lazy.load(Ordering::Relaxed) || is_gap(buffer) {
            return;
        }
        let info = {
            let queue = lock(&self.queue);
            if queue.lights.len() >= MAX_ARRIVED {
                return;
            }
            queue.info.clone()
        };
        let (Some(pts), Some(info)) = (buffer.pts(), info) else {
            return;
        };
        let started = Instant::now();
        let Some(light) = light_of(buffer, &info) else {
            return;
        };
        let took = started.elapsed();
        let mut queue = lock(&self.queue);
        queue.computed += 1;
        queue.time += took;
        queue.lights.push_back(Arrived {
            buffer: buffer.as_ptr() as usize,
            pts,
            light,
        });
    }

    fn event(&self, event: &gst::Event) {
        use gst::EventView;
        match event.view() {
            EventView::Caps(c) => {
                lock(&self.queue).info = gst_video::VideoInfo::from_caps(c.caps()).ok();
            }
            // The aggregator drops the frames it held at the flush.
            EventView::FlushStop(_) => lock(&self.queue).lights.clear(),
            _ => {}
        }
    }

    /// Forgets the lights and caps of a run that has stopped.
    fn stop(&self) {
        let mut queue = lock(&self.queue);
        queue.lights.clear();
        queue.info = None;
        self.lazy.store(false, Ordering::Relaxed);
    }

    /// Counts the lights computed since the last reading into `reading`.
    fn read_counts(&self, reading: &mut Reading) {
        let mut queue = lock(&self.queue);
        reading.arrival_decoded += std::mem::take(&mut queue.computed);
        reading.arrival_time += std::mem::take(&mut queue.time);
    }

    /// The light computed when `buffer` arrived, if it was. The aggregator hands
    /// frames on in the order they came, so lights of frames before it are no
    /// longer needed.
    fn take(&self, buffer: &gst::Buffer) -> Option<Light> {
        let pts = buffer.pts()?;
        let address = buffer.as_ptr() as usize;
        let mut queue = lock(&self.queue);
        match queue
            .lights
            .iter()
            .position(|a| a.buffer == address && a.pts == pts)
        {
            Some(at) => queue.lights.drain(..=at).next_back().map(|a| a.light),
            None => {
                // Not computed (the queue was full, or it came while lazy); lights
                // still queued before it in time are of frames already gone.
                queue.lights.retain(|a| a.pts >= pts);
                None
            }
        }
    }
}

/// A frame's light, if the frame can be read with `info`.
fn light_of(buffer: &gst::BufferRef, info: &gst_video::VideoInfo) -> Option<Light> {
    let frame = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer, info).ok()?;
    frame_view(&frame).map(|view| Light::from_frame(&view))
}

#[derive(Default)]
pub struct MonitorTrack {
    info: Option<gst_video::VideoInfo>,
    current: Option<Shown>,
    /// Lights computed as the pad's frames arrive; None before a pad is attached.
    arrivals: Option<Arc<ArrivalLights>>,
    /// Monitor frames consumed per face frame, a running mean from one.
    frames_per_face: Option<f64>,
    /// Monitor frames consumed since the last face frame counted in that mean: a
    /// face frame may take several calls of `consume` (it waits for monitor data,
    /// or for the video target), each with its own [`Reading`].
    consumed: u64,
    /// The last face frame counted in that mean.
    counted_face: Option<i64>,
    /// The fallback in force, if any.
    fallback: Option<Fallback>,
    /// Since when face frames may have been waiting for monitor frames.
    last_arrival: Option<Instant>,
    /// A warning about face frames waiting for a silent monitor stream is out.
    starvation_warned: bool,
}

impl MonitorTrack {
    /// Computes the lights of `pad`'s frames as they arrive, for this track.
    pub fn attach(&mut self, pad: &gst_base::AggregatorPad) {
        self.arrivals = Some(ArrivalLights::attach(pad));
    }

    /// A fresh track for a new run; caps that arrived before the start stay.
    pub fn restart(&mut self) {
        *self = MonitorTrack {
            info: self.info.take(),
            last_arrival: Some(Instant::now()),
            arrivals: self.arrivals.take(),
            ..MonitorTrack::default()
        };
    }

    /// Forgets the run that stopped, caps and all; its pad's probe stays.
    pub fn stop(&mut self) {
        if let Some(a) = &self.arrivals {
            a.stop();
        }
        *self = MonitorTrack {
            arrivals: self.arrivals.take(),
            ..MonitorTrack::default()
        };
    }

    pub fn set_info(&mut self, info: gst_video::VideoInfo) {
        self.info = Some(info);
    }

    /// After a flush of the monitor stream, nothing it showed is on screen any more.
    pub fn flush(&mut self) {
        self.current = None;
    }

    /// No face frame is waiting for the monitor stream (or it has data to give).
    pub fn flowing(&mut self) {
        self.last_arrival = Some(Instant::now());
        self.starvation_warned = false;
    }

    /// Whether face frames have waited for a silent monitor stream longer than
    /// `timeout`, reported once per silence: in a non-live pipeline the element
    /// waits for every monitor frame, so a branch that never produces would block
    /// the pipeline with no word.
    pub fn newly_starved(&mut self, timeout: Duration) -> bool {
        let silent = self
            .last_arrival
            .is_some_and(|t| t.elapsed() >= timeout.max(Duration::from_millis(100)));
        if silent && !self.starvation_warned {
            self.starvation_warned = true;
            return true;
        }
        false
    }

    /// Reads the monitor stream up to the face frame's running time `face_rt`
    /// less `offset` (ns), and decides which light the face frame gets.
    /// `deadline` is the aggregator's timeout: in a live pipeline, waiting is over.
    pub fn consume(
        &mut self,
        pad: &gst_base::AggregatorPad,
        face_rt: Option<gst::ClockTime>,
        deadline: bool,
        offset: i64,
        timeout: gst::ClockTime,
        reading: &mut Reading,
    ) -> Decision {
        let target = face_rt.map(|t| t.nseconds() as i64 - offset);
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
                        .max(timeout);
                    let light = self.arrivals.as_ref().and_then(|a| a.take(&buffer));
                    self.current = Some(Shown {
                        at,
                        valid_until: at.saturating_add(hold.nseconds() as i64),
                        frame: light.is_none().then_some(buffer),
                        light,
                    });
                    reading.frames += 1;
                    self.consumed += 1;
                    pad.drop_buffer();
                }
                None if pad.is_eos() => break End::Ended,
                None if deadline || target.is_none() => break End::Deadline,
                None => return Decision::Wait,
            }
        };
        if let Some(a) = &self.arrivals {
            a.read_counts(reading);
        }
        self.note_rate(target);
        let info = self.info.as_ref();
        let mut known = |c: &mut Shown| {
            let decoding = c.light.is_none();
            let started = Instant::now();
            match c.light(info) {
                Some(l) => {
                    if decoding {
                        reading.decoded = Some(started.elapsed());
                    }
                    Decision::Known(l, c.at)
                }
                None => Decision::Fallback(Fallback::Unreadable),
            }
        };
        let Some(target) = target else {
            return match self.current.as_mut() {
                Some(c) => known(c),
                None => Decision::Fallback(Fallback::NoTimestamp),
            };
        };
        // Decided by running times alone, so the outcome does not depend on how far
        // behind real time the element runs.
        match (self.current.as_mut(), end) {
            (Some(c), _) if target <= c.valid_until => known(c),
            (_, End::Ended) => Decision::Fallback(Fallback::Ended),
            (None, _) => Decision::Fallback(Fallback::NotStarted),
            (Some(_), End::Later | End::Deadline) => Decision::Fallback(Fallback::Stalled),
        }
    }

    /// Follows how many monitor frames each face frame consumes, and has their
    /// lights computed as they arrive only while that stays near one or below.
    fn note_rate(&mut self, face: Option<i64>) {
        if face.is_some() && face == self.counted_face {
            return;
        }
        self.counted_face = face;
        let consumed = std::mem::take(&mut self.consumed) as f64;
        let mean = self.frames_per_face.unwrap_or(1.0);
        let mean = mean + RATIO_WEIGHT * (consumed - mean);
        self.frames_per_face = Some(mean);
        if let Some(a) = &self.arrivals {
            a.lazy.store(mean > MAX_EAGER_RATIO, Ordering::Relaxed);
        }
    }

    /// Records the fallback in force for this frame; returns the change the user
    /// should hear about, if any. Having no monitor pad at all is not news.
    pub fn note_fallback(&mut self, fallback: Option<Fallback>) -> Option<Transition> {
        if self.fallback == fallback {
            return None;
        }
        let previous = std::mem::replace(&mut self.fallback, fallback);
        match (previous, fallback) {
            (_, Some(f)) if f != Fallback::NoMonitorPad => Some(Transition::FallbackStarted(f)),
            (Some(_), None) => Some(Transition::Returned),
            _ => None,
        }
    }
}

impl Shown {
    /// The frame's light, computed the first time a face frame needs it. None while
    /// the frame cannot be read; it is kept, in case its caps arrive.
    fn light(&mut self, info: Option<&gst_video::VideoInfo>) -> Option<Light> {
        if self.light.is_none()
            && let (Some(buffer), Some(info)) = (self.frame.as_ref(), info)
        {
            self.light = light_of(buffer, info);
            if self.light.is_some() {
                self.frame = None;
            }
        }
        self.light.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: u32 = 32;
    const H: u32 = 16;

    fn info() -> gst_video::VideoInfo {
        gst_video::VideoInfo::builder(gst_video::VideoFormat::Rgbx, W, H)
            .build()
            .unwrap()
    }

    /// A screen frame of one colour, shown at `ms`.
    fn screen(rgb: [u8; 3], ms: u64) -> gst::Buffer {
        let pixels: Vec<u8> = (0..W * H)
            .flat_map(|_| [rgb[0], rgb[1], rgb[2], 0])
            .collect();
        let mut buffer = gst::Buffer::from_mut_slice(pixels);
        buffer
            .get_mut()
            .unwrap()
            .set_pts(gst::ClockTime::from_mseconds(ms));
        buffer
    }

    /// Lights with the stream's caps seen, as the probe sees them.
    fn with_caps() -> ArrivalLights {
        gst::init().unwrap();
        let lights = ArrivalLights::default();
        lights.event(&gst::event::Caps::new(&info().to_caps().unwrap()));
        lights
    }

    fn computed(lights: &ArrivalLights) -> u64 {
        let mut reading = Reading::default();
        lights.read_counts(&mut reading);
        reading.arrival_decoded
    }

    #[test]
    fn a_frame_gets_the_light_computed_when_it_arrived() {
        let lights = with_caps();
        let frames = [
            screen([250, 250, 250], 0),
            screen([20, 40, 200], 33),
            screen([200, 90, 10], 67),
        ];
        for f in &frames {
            lights.arrive(f);
        }
        assert_eq!(computed(&lights), 3);
        let light = lights.take(&frames[1]);
        assert_eq!(light, light_of(&frames[1], &info()));
        assert_ne!(light, light_of(&frames[0], &info()));
        // The aggregator hands frames on in order: the first one is gone.
        assert_eq!(lights.take(&frames[0]), None);
        assert_eq!(lights.take(&frames[2]), light_of(&frames[2], &info()));
    }

    #[test]
    fn only_the_buffer_that_arrived_matches() {
        let lights = with_caps();
        let arrived = screen([250, 250, 250], 0);
        lights.arrive(&arrived);
        // Another buffer at the same time (after a seek, say) is not that frame.
        let other = screen([20, 40, 200], 0);
        assert_eq!(lights.take(&other), None);
        assert!(lights.take(&arrived).is_some());
    }

    #[test]
    fn a_frame_not_computed_lets_go_of_the_lights_before_it() {
        let lights = with_caps();
        let earlier = screen([250, 250, 250], 0);
        lights.arrive(&earlier);
        let missed = screen([20, 40, 200], 33);
        let later = screen([200, 90, 10], 67);
        lights.arrive(&later);
        assert_eq!(lights.take(&missed), None);
        assert_eq!(lights.take(&earlier), None);
        assert!(lights.take(&later).is_some());
    }

    #[test]
    fn nothing_is_computed_while_lazy_without_caps_or_after_a_flush_or_stop() {
        let lights = with_caps();
        lights.lazy.store(true, Ordering::Relaxed);
        let first = screen([250, 250, 250], 0);
        lights.arrive(&first);
        assert_eq!(lights.take(&first), None);
        assert_eq!(computed(&lights), 0);

        lights.lazy.store(false, Ordering::Relaxed);
        let second = screen([250, 250, 250], 33);
        lights.arrive(&second);
        lights.event(&gst::event::FlushStop::new(true));
        assert_eq!(lights.take(&second), None);

        lights.stop();
        let third = screen([250, 250, 250], 67);
        lights.arrive(&third);
        assert_eq!(lights.take(&third), None, "the caps went with the run");
    }

    #[test]
    fn frames_beyond_the_queue_get_their_light_later() {
        let lights = with_caps();
        let frames: Vec<_> = (0..MAX_ARRIVED as u64 + 3)
            .map(|k| screen([250, 250, 250], 33 * k))
            .collect();
        for f in &frames {
            lights.arrive(f);
        }
        assert_eq!(computed(&lights), MAX_ARRIVED as u64);
        // The first frames, which the aggregator hands on first, keep theirs.
        assert!(lights.take(&frames[0]).is_some());
        assert_eq!(lights.take(frames.last().unwrap()), None);
    }
}
