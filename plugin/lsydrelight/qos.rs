//! Quality of service: whether a face frame is already late, from the clock in
//! live pipelines and from downstream's QoS events, and the QoS message the
//! element posts for a frame it could only give a reused relighting.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

use gst::prelude::*;
use gst_base::prelude::*;

/// A frame's duration when its buffer and caps do not say.
const ASSUMED_FRAME: gst::ClockTime = gst::ClockTime::from_mseconds(33);

#[derive(Default)]
pub struct Qos {
    /// Downstream's earliest useful running time, from its QoS events.
    earliest: Mutex<Option<gst::ClockTime>>,
    /// Whether upstream is live, from the latency query.
    live: AtomicBool,
}

impl Qos {
    pub fn reset(&self) {
        *self.earliest.lock().unwrap_or_else(|p| p.into_inner()) = None;
    }

    pub fn set_live(&self, live: bool) {
        self.live.store(live, Ordering::Relaxed);
    }

    pub fn is_live(&self) -> bool {
        self.live.load(Ordering::Relaxed)
    }

    /// Takes a QoS event from downstream: skip what it will only drop, as the
    /// base classes do.
    pub fn on_event(&self, qos: &gst::event::Qos) {
        let (_, _, diff, timestamp) = qos.get();
        *self.earliest.lock().unwrap_or_else(|p| p.into_inner()) = timestamp.map(|t| {
            let late = if diff > 0 { 2 * diff } else { diff };
            gst::ClockTime::from_nseconds((t.nseconds() as i64 + late).max(0) as u64)
        });
    }

    /// Is a frame of this running time already past its deadline, by downstream's
    /// QoS or, in a live pipeline, by the clock?
    pub fn is_late(
        &self,
        element: &gst::Element,
        rt: Option<gst::ClockTime>,
        duration: Option<gst::ClockTime>,
    ) -> bool {
        let Some(rt) = rt else { return false };
        let frame = duration.unwrap_or(ASSUMED_FRAME);
        if let Some(earliest) = *self.earliest.lock().unwrap_or_else(|p| p.into_inner())
            && rt + frame < earliest
        {
            return true;
        }
        let (Some(clock), Some(base)) = (element.clock(), element.base_time()) else {
            return false;
        };
        if !self.is_live() {
            return false;
        }
        let latency = element
            .downcast_ref::<gst_base::Aggregator>()
            .and_then(|a| a.latency())
            .unwrap_or(gst::ClockTime::ZERO);
        let now = clock.time().saturating_sub(base);
        now > rt + latency + frame
    }
}

/// The QoS message for a late frame, with the element's counts of frames processed
/// in full and reused.
pub fn late_message(
    element: &gst::Element,
    segment: &gst::Segment,
    buffer: &gst::BufferRef,
    rt: Option<gst::ClockTime>,
    processed: u64,
    reused: u64,
) -> gst::Message {
    let stream_time = segment
        .downcast_ref::<gst::ClockTime>()
        .and_then(|time_segment| time_segment.to_stream_time(buffer.pts()?));
    gst::message::Qos::builder(true)
        .running_time(rt)
        .stream_time(stream_time)
        .timestamp(buffer.pts())
        .duration(buffer.duration())
        .stats(
            gst::format::Buffers::from_u64(processed),
            gst::format::Buffers::from_u64(reused),
        )
        .src(element)
        .build()
}
