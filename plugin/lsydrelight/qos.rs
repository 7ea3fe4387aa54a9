//! Quality of service: whether a face frame is already late, from the clock in
//! live pipelines and from downstream's QoS events; whether a live stream's
//! frames cost so much of their period that the denoising must go; and the QoS
//! message the element posts for a frame it could only give a reused relighting.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use gst::prelude::*;
use gst_base::prelude::*;

/// A frame's duration when its buffer and caps do not say.
const ASSUMED_FRAME: gst::ClockTime = gst::ClockTime::from_mseconds(33);

/// Weight of the latest frame in the running estimate of what a frame costs in full.
const COST_WEIGHT: f64 = 0.1;

/// Frames not found late over which a live stream's cost is judged: its
/// median over this many (3 s at 30 fps), so that the network's warm-up and
/// a busy moment do not count.
const JUDGED_OVER: usize = 90;

#[derive(Default)]
pub struct Qos {
    /// Downstream's earliest useful running time, from its QoS events.
    earliest: Mutex<Option<gst::ClockTime>>,
    /// Whether upstream is live, from the latency query.
    live: AtomicBool,
    /// What a frame not found late (relit, carried or passed through) has
    /// cost lately: an exponential average of their times in the element.
    full_cost: Mutex<FullCost>,
    /// Whether this stream's frames have shown they cannot afford the denoising.
    denoising_dropped: AtomicBool,
}

#[derive(Default)]
struct FullCost {
    average: Option<Duration>,
    /// The costs of the frames since the last judgement, up to [`JUDGED_OVER`].
    window: Vec<Duration>,
    /// The median of the last full window.
    median: Option<Duration>,
}

impl Qos {
    pub fn reset(&self) {
        *self.earliest.lock().unwrap_or_else(|p| p.into_inner()) = None;
        self.forget_cost();
    }

    /// Forgets what frames cost, and whether they could afford the denoising:
    /// new caps change both.
    pub fn forget_cost(&self) {
        *self.full_cost.lock().unwrap_or_else(|p| p.into_inner()) = FullCost::default();
        self.denoising_dropped.store(false, Ordering::Relaxed);
    }

    /// Takes the time a frame not found late took, for [`Qos::is_late`]'s
    /// estimate of when the next would be done.
    pub fn record_full_cost(&self, cost: Duration) {
        let mut full = self.full_cost.lock().unwrap_or_else(|p| p.into_inner());
        full.average = Some(match full.average {
            Some(a) => a.mul_f64(1.0 - COST_WEIGHT) + cost.mul_f64(COST_WEIGHT),
            None => cost,
        });
        full.window.push(cost);
        if full.window.len() == JUDGED_OVER {
            full.window.sort_unstable();
            full.median = Some(full.window[JUDGED_OVER / 2]);
            full.window.clear();
        }
    }

    /// The estimate of what a frame not found late costs; zero before any.
    pub fn full_cost(&self) -> Duration {
        self.full_cost
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .average
            .unwrap_or_default()
    }

    /// Whether a live stream whose frames last `duration` has just been found
    /// unable to afford the denoising, and the median cost that showed it:
    /// once, when the median frame not found late, over the last
    /// [`JUDGED_OVER`], cost more than that, so that most frames fall behind
    /// and only QoS's reuse keeps real time. The denoising is what can go
    /// without changing the light: half of a 2160p frame's time on 2 cores,
    /// where the median frame then took 42 ms of its 33 (1080p: 11-24 ms in a
    /// run that printed them, `cargo test --release --test live a_1080p`).
    /// From then [`Qos::denoising_dropped`] holds until new caps or a restart:
    /// a stream that dropped it does not take it back and forth, which would
    /// show its noise come and go.
    pub fn drops_denoising(&self, duration: Option<gst::ClockTime>) -> Option<Duration> {
        if !self.is_live() || self.denoising_dropped() {
            return None;
        }
        let period = Duration::from(duration.unwrap_or(ASSUMED_FRAME));
        let median = self
            .full_cost
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .median
            .filter(|m| *m > period)?;
        self.denoising_dropped.store(true, Ordering::Relaxed);
        Some(median)
    }

    /// Whether this stream has dropped the denoising ([`Qos::drops_denoising`]).
    pub fn denoising_dropped(&self) -> bool {
        self.denoising_dropped.load(Ordering::Relaxed)
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

    #[test]
    fn a_live_stream_that_cannot_afford_the_denoising_drops_it_once() {
        let period = Some(gst::ClockTime::from_mseconds(33));
        let qos = Qos::default();
        qos.set_live(true);
        // 2160p on 2 cores: most frames take more than the period, after a slow start.
        qos.record_full_cost(Duration::from_millis(900));
        for _ in 1..JUDGED_OVER - 1 {
            qos.record_full_cost(Duration::from_millis(42));
            assert!(
                qos.drops_denoising(period).is_none(),
                "judged before a window was full"
            );
        }
        qos.record_full_cost(Duration::from_millis(42));
        assert_eq!(qos.drops_denoising(period), Some(Duration::from_millis(42)));
        assert!(qos.denoising_dropped());
        // Said once; cheaper frames without it do not bring it back.
        for _ in 0..JUDGED_OVER {
            qos.record_full_cost(Duration::from_millis(5));
        }
        assert!(qos.drops_denoising(period).is_none());
        assert!(qos.denoising_dropped());
        // New caps judge afresh.
        qos.forget_cost();
        assert!(!qos.denoising_dropped());
    }

    #[test]
    fn a_stream_that_keeps_up_or_is_not_live_keeps_the_denoising() {
        let live = Qos::default();
        live.set_live(true);
        // 1080p on 2 cores on a busy minute: a third of the frames run the
        // network, and a few take longer than the period.
        for frame in 0..10 * JUDGED_OVER {
            let ms = match frame % 30 {
                0..=5 => 60,
                n if n % 3 == 0 => 30,
                _ => 28,
            };
            live.record_full_cost(Duration::from_millis(ms));
            assert!(live.drops_denoising(None).is_none());
        }
        // Transcoding a file: slower than real time is only slower.
        let file = Qos::default();
        for _ in 0..10 * JUDGED_OVER {
            file.record_full_cost(Duration::from_millis(100));
            assert!(file.drops_denoising(None).is_none());
        }
    }
}
