//! The `stats` property: what the element did and where its time went. The
//! element counts what happens around the policy (frames, monitor stream, side
//! stream, pasting); the policy counts its own decisions and the network's time.

use std::time::Instant;

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
    /// Seconds spent turning monitor frames into lights.
    pub monitor_light_seconds: f64,
    pub known_source: u64,
    pub predicted_source: u64,
    pub fallbacks: u64,
    /// Monitor frames that arrived.
    pub monitor_frames: u64,
    /// Monitor frames whose light was computed: the ones face frames used.
    pub monitor_decoded: u64,
    pub monitor_out: u64,
    pub monitor_dropped: u64,
    /// Target-stream frames that arrived, and those whose light was computed (the
    /// ones face frames used), and the seconds that took.
    pub target_stream_frames: u64,
    pub target_stream_decoded: u64,
    pub target_stream_light_seconds: f64,
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
        gst::Structure::builder("lsydrelight-stats")
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
            .field("smoothing-seconds", p.filter_seconds)
            .field("change-seconds", p.change_seconds)
            .field("decide-seconds", decide.max(0.0))
            .field("setup-seconds", s.setup)
            .field("finish-seconds", s.finish)
            .field("frame-seconds", s.frame)
            .field("monitor-light-seconds", self.monitor_light_seconds)
            .field("known-source", self.known_source)
            .field("predicted-source", self.predicted_source)
            .field("fallbacks", self.fallbacks)
            .field("resets", p.resets)
            .field("monitor-frames", self.monitor_frames)
            .field("monitor-decoded", self.monitor_decoded)
            .field("monitor-out", self.monitor_out)
            .field("monitor-dropped", self.monitor_dropped)
            .field("target-encodes", p.target_encodes)
            .field("source-encodes", p.source_encodes)
            .field("target-seconds", self.target_seconds)
            .field("target-stream-frames", self.target_stream_frames)
            .field("target-stream-decoded", self.target_stream_decoded)
            .field(
                "target-stream-light-seconds",
                self.target_stream_light_seconds,
            )
            .field("light-predictions", p.predictions)
            .field("non-finite", p.passed_non_finite)
            .build()
    }
}
