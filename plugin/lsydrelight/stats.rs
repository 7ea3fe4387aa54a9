//! The `stats` property: what the element did and where its time went. The
//! element counts what happens around the policy (frames, monitor stream, side
//! stream, pasting); the policy counts its own decisions and the network's time.

use std::time::Instant;

use super::monitor::Reading;
use crate::engine::PolicyCounts;

#[derive(Debug, Default, Clone, Copy)]
pub struct Stats {
    pub frames: u64,
    /// Seconds spent on face frames in all, and pasting the lighting change
    /// back, with the denoising the frame waited for.
    pub processing_seconds: f64,
    pub paste_seconds: f64,
    /// Seconds denoising (`denoise`), beside the network on frames it relit.
    pub denoise_seconds: f64,
    /// Frames copied to be written because upstream still held them, and the
    /// seconds the copies took.
    pub frames_copied: u64,
    pub copy_seconds: f64,
    /// Whether a live stream's frames proved too costly for the denoising,
    /// which then stopped (`qos`).
    pub denoising_dropped: bool,
    pub known_source: u64,
    pub predicted_source: u64,
    /// Frames without a monitor stream relit from `source-preset`'s light (counted
    /// in `known_source` too).
    pub assumed_source: u64,
    pub fallbacks: u64,
    /// The monitor stream's frames and their lights.
    pub monitor: StreamLights,
    pub monitor_out: u64,
    pub monitor_dropped: u64,
    /// The video target's frames and their lights.
    pub target_stream: StreamLights,
    /// Seconds encoding target lights on the streaming thread (first targets,
    /// crossfades, video targets).
    pub target_seconds: f64,
    /// Face detector runs, and seconds following the face (detector and tracker).
    pub face_detections: u64,
    pub face_seconds: f64,
    /// Where the rest of a face frame's time goes, stage by stage ([`Stages`]).
    pub stages: Stages,
    /// The policy's counts as of the last frame; kept after stop, so the last
    /// run's figures stay readable.
    pub policy: PolicyCounts,
}

/// A stream of screen frames (the monitor stream, the video target) turned into lights.
#[derive(Debug, Default, Clone, Copy)]
pub struct StreamLights {
    /// Frames consumed.
    pub frames: u64,
    /// Lights computed on the element's thread, when a face frame needed them,
    /// and the seconds they took there: what face frames waited for.
    pub decoded: u64,
    pub light_seconds: f64,
    /// Lights computed on the stream's own thread as its frames arrived, and the
    /// seconds they took there.
    pub arrival_decoded: u64,
    pub arrival_seconds: f64,
}

impl StreamLights {
    pub fn add(&mut self, reading: &Reading) {
        self.frames += reading.frames;
        if let Some(t) = reading.decoded {
            self.decoded += 1;
            self.light_seconds += t.as_secs_f64();
        }
        self.arrival_decoded += reading.arrival_decoded;
        self.arrival_seconds += reading.arrival_time.as_secs_f64();
    }

    fn write(&self, s: gst::structure::Builder, stream: &str) -> gst::structure::Builder {
        s.field(format!("{stream}-frames"), self.frames)
            .field(format!("{stream}-decoded"), self.decoded)
            .field(format!("{stream}-light-seconds"), self.light_seconds)
            .field(format!("{stream}-arrival-decoded"), self.arrival_decoded)
            .field(format!("{stream}-arrival-seconds"), self.arrival_seconds)
    }
}

/// Seconds a face frame spends outside the network, the crop and the paste,
/// summed over frames: what the stage table calls the rest, by name.
#[derive(Debug, Default, Clone, Copy)]
pub struct Stages {
    /// Taking the inference lock, bringing the policy up to date (target fades)
    /// and mapping the frame for reading.
    pub setup: f64,
    /// In the per-frame policy in all: the crop, the network, smoothing, building
    /// the lighting change, and deciding.
    pub policy: f64,
    /// After the paste: the region-of-interest meta, warnings, statistics.
    pub finish: f64,
    /// A face frame's whole turn in the element, up to handing it downstream:
    /// the above and its monitor frames, the predicted light shown on
    /// `monitor_src`, the QoS check and the monitor-frame meta.
    pub frame: f64,
}

/// Wall time since the last lap, lap by lap.
pub struct Laps(Instant);

impl Laps {
    pub fn start() -> Laps {
        Laps(Instant::now())
    }

    /// Seconds since the start or the last lap.
    pub fn lap(&mut self) -> f64 {
        let now = Instant::now();
        let seconds = now.duration_since(self.0).as_secs_f64();
        self.0 = now;
        seconds
    }
}

impl Stats {
    pub fn to_structure(self) -> gst::Structure {
        let p = &self.policy;
        let s = &self.stages;
        // The policy's time that is not the crop, the network, smoothing or the change.
        let decide =
            s.policy - p.crop_seconds - p.network_seconds - p.filter_seconds - p.change_seconds;
        let builder = gst::Structure::builder("lsydrelight-stats")
            .field("frames", self.frames)
            .field("relit", p.relit)
            .field("passed-through", p.passed_non_finite)
            .field("skipped-dark", p.passed_dark)
            .field("skipped-no-face", p.passed_no_face)
            .field("face-detections", self.face_detections)
            .field("face-seconds", self.face_seconds)
            .field("skipped-absent", p.passed_absent)
            .field("skipped-same-light", p.passed_same_light)
            .field("reused-interval", p.reused_interval)
            .field("qos-reused", p.reused_late)
            .field("processing-seconds", self.processing_seconds)
            .field("network-seconds", p.network_seconds)
            .field("crop-seconds", p.crop_seconds)
            .field("paste-seconds", self.paste_seconds)
            .field("denoise-seconds", self.denoise_seconds)
            .field("frames-copied", self.frames_copied)
            .field("copy-seconds", self.copy_seconds)
            .field("denoising-dropped", self.denoising_dropped)
            .field("smoothing-seconds", p.filter_seconds)
            .field("change-seconds", p.change_seconds)
            .field("decide-seconds", decide.max(0.0))
            .field("setup-seconds", s.setup)
            .field("finish-seconds", s.finish)
            .field("frame-seconds", s.frame)
            .field("known-source", self.known_source)
            .field("predicted-source", self.predicted_source)
            .field("assumed-source", self.assumed_source)
            .field("fallbacks", self.fallbacks)
            .field("resets", p.resets)
            .field("monitor-out", self.monitor_out)
            .field("monitor-dropped", self.monitor_dropped)
            .field("target-encodes", p.target_encodes)
            .field("source-encodes", p.source_encodes)
            .field("spread-decodes", p.spread_decodes)
            .field("target-seconds", self.target_seconds)
            .field("light-predictions", p.predictions)
            .field("non-finite", p.passed_non_finite);
        let builder = self.monitor.write(builder, "monitor");
        self.target_stream.write(builder, "target-stream").build()
    }
}
