//! Quality of service: whether a face frame is already late, from the clock in
//! live pipelines and from downstream's QoS events, and the QoS message the
//! element posts for a frame it could only give a reused relighting.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use gst::prelude::*;
use gst_base::prelude::*;

/// A frame's duration when its buffer and caps do not say.
const ASSUMED_FRAME: gst::ClockTime = gst::ClockTime::from_mseconds(33);

/// Weight of the latest frame in the running estimate of what a frame costs in full.
const COST_WEIGHT: f64 = 0.1;

#[derive(Default)]
pub struct Qos {
    /// Downstream's earliest useful running time, from its QoS events.
    earliest: Mutex<Option<gst::ClockTime>>,
    /// Whether upstream is live, from the latency query.
    live: AtomicBool,
    /// What a frame not found late (relit, carried or passed through) has
    /// cost lately: an exponential average of their times in the element.
    full_cost: Mutex<Option<Duration>>,
}

impl Qos {
    pub fn reset(&self) {
        *self.earliest.lock().unwrap_or_else(|p| p.into_inner()) = None;
        self.forget_cost();
    }

    /// Forgets what frames cost: new caps change it.
    pub fn forget_cost(&self) {
        *self.full_cost.lock().unwrap_or_else(|p| p.into_inner()) = None;
    }

    /// Takes the time a frame not found late took, for [`Qos::is_late`]'s
    /// estimate of when the next would be done.
    pub fn record_full_cost(&self, cost: Duration) {
        let mut average = self.full_cost.lock().unwrap_or_else(|p| p.into_inner());
        *average = Some(match *average {
            Some(a) => a.mul_f64(1.0 - COST_WEIGHT) + cost.mul_f64(COST_WEIGHT),
            None => cost,
        });
    }

    /// The estimate of what a frame not found late costs; zero before any.
    pub fn full_cost(&self) -> Duration {
        (*self.full_cost.lock().unwrap_or_else(|p| p.into_inner())).unwrap_or_default()
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
    /// QoS, or in a live pipeline would it be by the clock once processed as
    /// frames not found late have been lately? A frame found late then costs
    /// the paste alone, so it leaves in time rather than be dropped
    /// downstream, and the element catches up.
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
        // At most a frame: a frame that starts past its deadline is late
        // whatever it costs, and one that starts before it is not found late
        // on an estimate that a slow start or a stall has left high, which
        // (frames found late not being counted) could otherwise stay high.
        let cost = gst::ClockTime::try_from(self.full_cost()).map_or(frame, |c| c.min(frame));
        now + cost > rt + latency + frame
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cost_estimate_follows_the_frames_and_resets() {
        let qos = Qos::default();
        assert_eq!(qos.full_cost(), Duration::ZERO);
        qos.record_full_cost(Duration::from_millis(30));
        assert_eq!(qos.full_cost(), Duration::from_millis(30));
        // A slow frame moves it a tenth of the way: a spike does not make every
        // next frame late.
        qos.record_full_cost(Duration::from_millis(130));
        assert_eq!(qos.full_cost(), Duration::from_millis(40));
        qos.reset();
        assert_eq!(qos.full_cost(), Duration::ZERO);
    }
}
