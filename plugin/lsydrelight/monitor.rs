//! The monitor stream and its alignment rule.
//!
//! Each face frame uses the monitor frame shown at its running time minus
//! `monitor-offset`: the last monitor frame at or before that time, while it is
//! still on screen (its duration or `monitor-timeout`, whichever is longer).
//! Monitor frames a newer one replaces before a face frame needs them are never
//! decoded. Without usable monitor content (no pad, not yet started, stalled,
//! ended, unreadable) the face frame is relit with the predicted light, and a
//! warning says so once, when that starts.

use std::time::{Duration, Instant};

use gst_base::prelude::*;

use crate::light::Light;

use super::video::{frame_view, is_gap, running_time};

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
    /// Whether a monitor frame's light was computed, and how long it took.
    pub decoded: Option<Duration>,
}

#[derive(Default)]
pub struct MonitorTrack {
    info: Option<gst_video::VideoInfo>,
    current: Option<Shown>,
    /// The fallback in force, if any.
    fallback: Option<Fallback>,
    /// Since when face frames may have been waiting for monitor frames.
    last_arrival: Option<Instant>,
    /// A warning about face frames waiting for a silent monitor stream is out.
    starvation_warned: bool,
}

impl MonitorTrack {
    /// A fresh track for a new run; caps that arrived before the start stay.
    pub fn restart(&mut self) {
        *self = MonitorTrack {
            info: self.info.take(),
            last_arrival: Some(Instant::now()),
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
                    self.current = Some(Shown {
                        at,
                        valid_until: at.saturating_add(hold.nseconds() as i64),
                        frame: Some(buffer),
                        light: None,
                    });
                    reading.frames += 1;
                    pad.drop_buffer();
                }
                None if pad.is_eos() => break End::Ended,
                None if deadline || target.is_none() => break End::Deadline,
                None => return Decision::Wait,
            }
        };
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
