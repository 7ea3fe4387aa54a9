//! What the user set: the element's properties, their defaults, and their
//! ParamSpecs (the blurbs `gst-inspect-1.0 lsydrelight` shows). Nothing here is
//! derived from the stream; decoded targets and the like are state.

use std::path::PathBuf;
use std::sync::LazyLock;

use gst::glib;
use gst::prelude::*;

use super::ExecutionProvider;
use super::target::TargetSource;
use crate::engine::{Skips, Temporal};
use crate::monitor_match::MatchSettings;
use crate::paths;
use crate::targets::{Preset, View, panorama};

pub const DEFAULT_THREADS: u32 = 2;
const MAX_MONITOR_OFFSET: i64 = 10_000_000_000;
const DEFAULT_MONITOR_TIMEOUT: gst::ClockTime = gst::ClockTime::from_seconds(1);
/// About one frame at 30 fps: relighting a 1080p frame takes 10 ms on an idle 2-core machine,
/// and live sinks drop what arrives later than the latency the pipeline reported.
const DEFAULT_PROCESSING_LATENCY: gst::ClockTime = gst::ClockTime::from_mseconds(33);
const DEFAULT_RESET_GAP: gst::ClockTime = gst::ClockTime::from_seconds(1);
const DEFAULT_CROP_CENTRE: f64 = 0.5;
const DEFAULT_CROP_SIZE: f64 = 1.0;
const DEFAULT_FEATHER: f64 = 0.5;
const DEFAULT_DENOISE: bool = true;
const DEFAULT_QOS: bool = true;
/// Without a monitor stream the source light is predicted, as in the paper.
const DEFAULT_SOURCE_PRESET: Preset = Preset::None;
const DEFAULT_TARGET_TRANSITION: gst::ClockTime = gst::ClockTime::from_mseconds(500);
const MAX_TARGET_TRANSITION: gst::ClockTime = gst::ClockTime::from_seconds(60);

/// The square face region, as fractions of the frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CropRegion {
    pub x: f64,
    pub y: f64,
    /// Side, as a fraction of the frame's shorter side.
    pub size: f64,
}

#[derive(Debug, Clone)]
pub struct Settings {
    pub model_location: PathBuf,
    pub ort_library: PathBuf,
    pub provider: ExecutionProvider,
    pub threads: u32,
    pub target_location: PathBuf,
    pub target_preset: Preset,
    /// An equirectangular environment map; empty for none.
    pub target_environment: PathBuf,
    /// How the monitor looks into the environment map.
    pub target_view: View,
    /// Face running time over which a new target fades in.
    pub target_transition: gst::ClockTime,
    /// Colour the face by the target spread evenly (`engine::spread_colour`).
    pub spread_colour: bool,
    /// Nanoseconds by which the monitor content that lit a face frame precedes it.
    pub monitor_offset: i64,
    pub monitor_timeout: gst::ClockTime,
    /// The light the face is lit by while no monitor stream says: `None` predicts it.
    pub source_preset: Preset,
    /// Time the element takes for a frame, added to the latency it reports.
    pub processing_latency: gst::ClockTime,
    pub temporal: Temporal,
    /// Follow the face with the detector; otherwise `crop` fixes the region.
    pub face_tracking: bool,
    pub face_detector_location: PathBuf,
    /// Which face to follow: 0 the largest, 1 the next, ...
    pub face_index: u32,
    pub crop: CropRegion,
    /// Fade width at the face region's inner edges, as a fraction of the region.
    pub feather: f64,
    /// Take the camera's noise out of the face's detail over time before
    /// relighting it (`frame::DetailDenoiser`).
    pub denoise: bool,
    pub reset_gap: gst::ClockTime,
    pub skips: Skips,
    pub qos: bool,
    /// Check that the light on the face follows the monitor stream, and say so on the bus.
    pub match_check: bool,
    pub matching: MatchSettings,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            model_location: paths::default_model(),
            ort_library: paths::default_ort_library(),
            provider: ExecutionProvider::Cpu,
            threads: DEFAULT_THREADS,
            target_location: paths::default_target(),
            target_preset: Preset::None,
            target_environment: PathBuf::new(),
            target_view: View::default(),
            target_transition: DEFAULT_TARGET_TRANSITION,
            spread_colour: true,
            monitor_offset: 0,
            monitor_timeout: DEFAULT_MONITOR_TIMEOUT,
            source_preset: DEFAULT_SOURCE_PRESET,
            processing_latency: DEFAULT_PROCESSING_LATENCY,
            temporal: Temporal::default(),
            face_tracking: true,
            face_detector_location: paths::default_face_detector(),
            face_index: 0,
            crop: CropRegion {
                x: DEFAULT_CROP_CENTRE,
                y: DEFAULT_CROP_CENTRE,
                size: DEFAULT_CROP_SIZE,
            },
            feather: DEFAULT_FEATHER,
            denoise: DEFAULT_DENOISE,
            reset_gap: DEFAULT_RESET_GAP,
            skips: Skips::default(),
            qos: DEFAULT_QOS,
            match_check: false,
            matching: MatchSettings::default(),
        }
    }
}

fn path_value(p: &std::path::Path) -> glib::Value {
    p.to_string_lossy().into_owned().to_value()
}

fn path_of(v: &glib::Value) -> PathBuf {
    PathBuf::from(v.get::<Option<String>>().ok().flatten().unwrap_or_default())
}

impl Settings {
    /// The skips the policy applies. While the face is followed, a frame reaches the
    /// network only with a face found, so the presence check would only repeat it.
    pub fn policy_skips(&self) -> Skips {
        Skips {
            skip_absent: self.skips.skip_absent && !self.face_tracking,
            ..self.skips
        }
    }

    /// The target the settings name: a preset, else an environment map, else the image.
    pub fn target_source(&self) -> TargetSource {
        if self.target_preset != Preset::None {
            TargetSource::Preset(self.target_preset)
        } else if !self.target_environment.as_os_str().is_empty() {
            TargetSource::Environment(self.target_environment.clone(), self.target_view)
        } else {
            TargetSource::Image(self.target_location.clone())
        }
    }

    /// Sets a property by name; false for a name that is not a setting (the
    /// element handles those: `stats`).
    pub fn set(&mut self, name: &str, v: &glib::Value) -> bool {
        let checked = "GObject checked the value's type";
        match name {
            "model-location" => self.model_location = path_of(v),
            "ort-library" => self.ort_library = path_of(v),
            "execution-provider" => self.provider = v.get().expect(checked),
            "threads" => self.threads = v.get().expect(checked),
            "target-location" => self.target_location = path_of(v),
            "target-preset" => self.target_preset = v.get().expect(checked),
            "target-environment" => self.target_environment = path_of(v),
            "target-fov" => self.target_view.fov = v.get().expect(checked),
            "target-yaw" => self.target_view.yaw = v.get().expect(checked),
            "target-pitch" => self.target_view.pitch = v.get().expect(checked),
            "target-exposure" => self.target_view.exposure = v.get().expect(checked),
            "target-transition" => {
                self.target_transition = gst::ClockTime::from_nseconds(v.get().expect(checked))
            }
            "monitor-offset" => self.monitor_offset = v.get().expect(checked),
            "monitor-timeout" => {
                self.monitor_timeout = gst::ClockTime::from_nseconds(v.get().expect(checked))
            }
            "source-preset" => self.source_preset = v.get().expect(checked),
            "processing-latency" => {
                self.processing_latency = gst::ClockTime::from_nseconds(v.get().expect(checked))
            }
            "alpha" => self.temporal.alpha = v.get().expect(checked),
            "beta" => self.temporal.beta = v.get().expect(checked),
            "average-frames" => {
                self.temporal.average_frames = v.get::<u32>().expect(checked) as usize
            }
            "prediction-weight" => self.temporal.prediction_weight = v.get().expect(checked),
            "colour-tracking" => self.temporal.colour_tracking = v.get().expect(checked),
            "spread-colour" => self.spread_colour = v.get().expect(checked),
            "face-tracking" => self.face_tracking = v.get().expect(checked),
            "face-detector-location" => self.face_detector_location = path_of(v),
            "face-index" => self.face_index = v.get().expect(checked),
            "crop-x" => self.crop.x = v.get().expect(checked),
            "crop-y" => self.crop.y = v.get().expect(checked),
            "crop-size" => self.crop.size = v.get().expect(checked),
            "feather" => self.feather = v.get().expect(checked),
            "denoise" => self.denoise = v.get().expect(checked),
            "reset-gap" => self.reset_gap = gst::ClockTime::from_nseconds(v.get().expect(checked)),
            "reuse-interval" => self.skips.reuse_interval = v.get().expect(checked),
            "reuse-threshold" => self.skips.reuse_threshold = v.get::<f64>().expect(checked) as f32,
            "reuse-light-threshold" => {
                self.skips.reuse_light_threshold = v.get::<f64>().expect(checked) as f32
            }
            "skip-same-light" => self.skips.skip_same_light = v.get().expect(checked),
            "same-light-tolerance" => {
                self.skips.same_light_tolerance = v.get::<f64>().expect(checked) as f32
            }
            "skip-absent" => self.skips.skip_absent = v.get().expect(checked),
            "presence-threshold" => {
                self.skips.presence_threshold = v.get::<f64>().expect(checked) as f32
            }
            "qos" => self.qos = v.get().expect(checked),
            "match-check" => self.match_check = v.get().expect(checked),
            "match-window" => self.matching.window = v.get().expect(checked),
            "match-threshold" => self.matching.threshold = v.get().expect(checked),
            _ => return false,
        }
        true
    }

    /// A property by name; None for a name that is not a setting.
    pub fn get(&self, name: &str) -> Option<glib::Value> {
        Some(match name {
            "model-location" => path_value(&self.model_location),
            "ort-library" => path_value(&self.ort_library),
            "execution-provider" => self.provider.to_value(),
            "threads" => self.threads.to_value(),
            "target-location" => path_value(&self.target_location),
            "target-preset" => self.target_preset.to_value(),
            "target-environment" => path_value(&self.target_environment),
            "target-fov" => self.target_view.fov.to_value(),
            "target-yaw" => self.target_view.yaw.to_value(),
            "target-pitch" => self.target_view.pitch.to_value(),
            "target-exposure" => self.target_view.exposure.to_value(),
            "target-transition" => self.target_transition.nseconds().to_value(),
            "monitor-offset" => self.monitor_offset.to_value(),
            "monitor-timeout" => self.monitor_timeout.nseconds().to_value(),
            "source-preset" => self.source_preset.to_value(),
            "processing-latency" => self.processing_latency.nseconds().to_value(),
            "alpha" => self.temporal.alpha.to_value(),
            "beta" => self.temporal.beta.to_value(),
            "average-frames" => (self.temporal.average_frames as u32).to_value(),
            "prediction-weight" => self.temporal.prediction_weight.to_value(),
            "colour-tracking" => self.temporal.colour_tracking.to_value(),
            "spread-colour" => self.spread_colour.to_value(),
            "face-tracking" => self.face_tracking.to_value(),
            "face-detector-location" => path_value(&self.face_detector_location),
            "face-index" => self.face_index.to_value(),
            "crop-x" => self.crop.x.to_value(),
            "crop-y" => self.crop.y.to_value(),
            "crop-size" => self.crop.size.to_value(),
            "feather" => self.feather.to_value(),
            "denoise" => self.denoise.to_value(),
            "reset-gap" => self.reset_gap.nseconds().to_value(),
            "reuse-interval" => self.skips.reuse_interval.to_value(),
            "reuse-threshold" => (self.skips.reuse_threshold as f64).to_value(),
            "reuse-light-threshold" => (self.skips.reuse_light_threshold as f64).to_value(),
            "skip-same-light" => self.skips.skip_same_light.to_value(),
            "same-light-tolerance" => (self.skips.same_light_tolerance as f64).to_value(),
            "skip-absent" => self.skips.skip_absent.to_value(),
            "presence-threshold" => (self.skips.presence_threshold as f64).to_value(),
            "qos" => self.qos.to_value(),
            "match-check" => self.match_check.to_value(),
            "match-window" => self.matching.window.to_value(),
            "match-threshold" => self.matching.threshold.to_value(),
            _ => return None,
        })
    }
}

/// The element's properties.
pub fn properties() -> &'static [glib::ParamSpec] {
    static PROPERTIES: LazyLock<Vec<glib::ParamSpec>> = LazyLock::new(|| {
        let d = Settings::default();
        let path = |p: &PathBuf| p.to_str().unwrap_or("").to_owned();
        vec![
            glib::ParamSpecString::builder("model-location")
                .nick("Model")
                .blurb("Folder of the personalised model (model.json and its ONNX stages); the default, models/starter, is trained on many people; `lsydrelight train` makes your own; models/starter-int8 and models/default-int8 are int8 variants: a faster network for a little more error (docs/benchmark.md)")
                .default_value(Some(path(&d.model_location).as_str()))
                .mutable_ready()
                .build(),
            glib::ParamSpecString::builder("ort-library")
                .nick("ONNX Runtime library")
                .blurb("Path of libonnxruntime.so (1.31, from the onnxruntime Python wheel); LSYDRELIGHT_ORT_LIBRARY sets the default. One library per process")
                .default_value(Some(path(&d.ort_library).as_str()))
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
                .blurb("PNG image of the monitor content to relight to (as a screen capture would show it); used when target-preset is none and target-environment is empty; can change while playing (default: the shipped models/targets/studio.png)")
                .default_value(Some(path(&d.target_location).as_str()))
                .mutable_playing()
                .build(),
            glib::ParamSpecEnum::builder_with_default("target-preset", d.target_preset)
                .nick("Target preset")
                .blurb("A built-in target light, as monitor content; takes precedence over target-environment and target-location; none (the default) uses those; can change while playing")
                .mutable_playing()
                .build(),
            glib::ParamSpecString::builder("target-environment")
                .nick("Target environment map")
                .blurb("Equirectangular panorama (Radiance .hdr, OpenEXR .exr, PNG or JPEG; twice as wide as high, its centre straight ahead) whose part in front of the viewer is the target monitor light; used when target-preset is none; empty (the default) for none; can change while playing")
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("target-fov")
                .nick("Environment field of view")
                .blurb("Degrees of the environment map the monitor shows across (vertically half as many), as the paper's 180-degree monitor light (default 180)")
                .minimum(1.0)
                .maximum(360.0)
                .default_value(panorama::DEFAULT_FOV)
                .mutable_playing()
                .controllable()
                .build(),
            glib::ParamSpecDouble::builder("target-yaw")
                .nick("Environment yaw")
                .blurb("Degrees the viewer turns to the right in the environment map (the picture moves left); animatable with GstController (default 0)")
                .minimum(-360.0)
                .maximum(360.0)
                .default_value(0.0)
                .mutable_playing()
                .controllable()
                .build(),
            glib::ParamSpecDouble::builder("target-pitch")
                .nick("Environment pitch")
                .blurb("Degrees the view tilts up in the environment map; animatable with GstController (default 0)")
                .minimum(-90.0)
                .maximum(90.0)
                .default_value(0.0)
                .mutable_playing()
                .controllable()
                .build(),
            glib::ParamSpecDouble::builder("target-exposure")
                .nick("Environment exposure")
                .blurb("Stops by which the environment map's linear light is scaled before it is clipped to the monitor's range [0, 1] (its tone mapping); animatable (default 0)")
                .minimum(-20.0)
                .maximum(20.0)
                .default_value(0.0)
                .mutable_playing()
                .controllable()
                .build(),
            glib::ParamSpecUInt64::builder("target-transition")
                .nick("Target transition")
                .blurb("Nanoseconds of the face stream's running time over which a new target light (preset, file, environment map or its view) crossfades in; 0 jumps (default 500000000: half a second)")
                .maximum(MAX_TARGET_TRANSITION.nseconds())
                .default_value(DEFAULT_TARGET_TRANSITION.nseconds())
                .mutable_playing()
                .build(),
            glib::ParamSpecInt64::builder("monitor-offset")
                .nick("Monitor offset")
                .blurb("Nanoseconds by which the monitor content that lit a face frame precedes it (display and camera latency); a negative offset, for a screen capture that lags, adds as much latency")
                .minimum(-MAX_MONITOR_OFFSET)
                .maximum(MAX_MONITOR_OFFSET)
                .default_value(0)
                .mutable_playing()
                .build(),
            glib::ParamSpecUInt64::builder("monitor-timeout")
                .nick("Monitor timeout")
                .blurb("Nanoseconds a monitor frame stays on screen without a newer one (or its duration, if longer); after that the monitor stream counts as stalled and the predicted light is used (a target_sink stream's frame, as stalled, and its last frame stays the target). In a non-live pipeline, also how long face frames wait for a monitor stream that sends nothing before a warning says so")
                .default_value(DEFAULT_MONITOR_TIMEOUT.nseconds())
                .mutable_playing()
                .build(),
            glib::ParamSpecEnum::builder_with_default("source-preset", d.source_preset)
                .nick("Source preset")
                .blurb("Without a monitor stream connected, the light the face is lit by, as monitor content: none (the default) predicts it from the face (the paper's unknown-source mode), which reads a face lit by the room as one under a dim screen, so that a target adds its light to the room's; a preset (soft-front: a face lit from the front) states the light the relighting replaces, for a stronger change (docs/targets.md); a target equal to it passes the face unchanged; can change while playing")
                .mutable_playing()
                .build(),
            glib::ParamSpecUInt64::builder("processing-latency")
                .nick("Processing latency")
                .blurb("Nanoseconds the element may take to relight a frame, added to the latency it reports so that live sinks allow for it (it starts relighting only once the frame's monitor light is in or its wait has timed out)")
                .maximum(gst::ClockTime::SECOND.nseconds())
                .default_value(DEFAULT_PROCESSING_LATENCY.nseconds())
                .mutable_ready()
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
            glib::ParamSpecFloat::builder("prediction-weight")
                .nick("Predicted light smoothing")
                .blurb("Without a monitor stream, weight w of each frame's predicted light in its exponential smoothing, P = w*p_t + (1-w)*P_(t-1), so relit brightness does not pump; 1 turns it off")
                .minimum(0.0)
                .maximum(1.0)
                .default_value(d.temporal.prediction_weight)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoolean::builder("colour-tracking")
                .nick("Predicted light's colour from the face")
                .blurb("Let the light predicted from the face (the source light without a monitor stream, monitor_src, match-check) take its colour changes from the face's own: skin keeps its colour, so they come from the light (beyond the paper); false keeps the light decoder's colour")
                .default_value(d.temporal.colour_tracking)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoolean::builder("spread-colour")
                .nick("Target's colour from its mean")
                .blurb("Colour the face by the target light spread evenly over the screen (its mean colour), and light it where the target falls: the network gives a light on part of the screen (a key from one side) too little of its colour (beyond the paper). Runs the decoder a second time every 4th network frame; false saves that")
                .default_value(d.spread_colour)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoolean::builder("face-tracking")
                .nick("Follow the face")
                .blurb("Find the face with the face detector and relight the square around it, fading in and out as a face comes and goes; false fixes the region with crop-x, crop-y and crop-size")
                .default_value(d.face_tracking)
                .mutable_ready()
                .build(),
            glib::ParamSpecString::builder("face-detector-location")
                .nick("Face detector")
                .blurb("The face detector's ONNX file (BlazeFace short-range); the shipped one is models/face/blazeface.onnx")
                .default_value(Some(path(&d.face_detector_location).as_str()))
                .mutable_ready()
                .build(),
            glib::ParamSpecUInt::builder("face-index")
                .nick("Which face")
                .blurb("With several faces in view, which to follow: 0 the largest, 1 the next largest, and so on")
                .maximum(15)
                .default_value(d.face_index)
                .mutable_ready()
                .build(),
            glib::ParamSpecDouble::builder("crop-x")
                .nick("Face region centre x")
                .blurb("With face-tracking=false: horizontal centre of the square face region, as a fraction of the frame width")
                .minimum(0.0)
                .maximum(1.0)
                .default_value(DEFAULT_CROP_CENTRE)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("crop-y")
                .nick("Face region centre y")
                .blurb("With face-tracking=false: vertical centre of the square face region, as a fraction of the frame height")
                .minimum(0.0)
                .maximum(1.0)
                .default_value(DEFAULT_CROP_CENTRE)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("crop-size")
                .nick("Face region size")
                .blurb("With face-tracking=false: side of the square face region as a fraction of the frame's shorter side (1: a head-and-shoulders square of full height)")
                .minimum(0.05)
                .maximum(1.0)
                .default_value(DEFAULT_CROP_SIZE)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("feather")
                .nick("Feather")
                .blurb("Width, as a fraction of the face region, over which the relighting fades out beyond the head and shoulders it relights whole")
                .minimum(0.0)
                .maximum(1.0)
                .default_value(DEFAULT_FEATHER)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoolean::builder("denoise")
                .nick("Denoise the face")
                .blurb("Take the camera's noise out of the detail round the face, over time, before relighting it: still detail is averaged over about 12 frames, moving detail taken as it is; the relit face then flickers less than the camera's picture. It runs beside the network, on the other core; frames late for QoS skip it, and a live stream whose median frame costs more than its period drops it (with a warning) until new caps. false keeps the frame's own detail, noise and all")
                .default_value(d.denoise)
                .mutable_playing()
                .build(),
            glib::ParamSpecUInt64::builder("reset-gap")
                .nick("Reset gap")
                .blurb("Nanoseconds between face frames beyond which the temporal state starts afresh")
                .default_value(DEFAULT_RESET_GAP.nseconds())
                .mutable_playing()
                .build(),
            glib::ParamSpecUInt::builder("reuse-interval")
                .nick("Reuse interval")
                .blurb("The network runs at least every this many frames; in between, the last relighting is carried onto each frame, unless the picture or the light changed beyond the thresholds below (1: every frame runs the network)")
                .minimum(1)
                .maximum(30)
                .default_value(d.skips.reuse_interval)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("reuse-threshold")
                .nick("Reuse image threshold")
                .blurb("Mean absolute change of the network's input (sRGB in [0, 1]) since the network last ran beyond which it runs at once (a cut, a big motion); a still face's sensor noise is about 0.0044")
                .minimum(0.0)
                .maximum(1.0)
                .default_value(d.skips.reuse_threshold as f64)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("reuse-light-threshold")
                .nick("Reuse light threshold")
                .blurb("Mean absolute change of the averaged source light (linear) since the network last ran beyond which it runs at once")
                .minimum(0.0)
                .maximum(1.0)
                .default_value(d.skips.reuse_light_threshold as f64)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoolean::builder("skip-same-light")
                .nick("Skip when source is target")
                .blurb("Pass frames through when the source light equals the target light within same-light-tolerance")
                .default_value(d.skips.skip_same_light)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("same-light-tolerance")
                .nick("Same light tolerance")
                .blurb("Mean absolute difference of source and target light (linear) under which they count as the same")
                .minimum(0.0)
                .maximum(1.0)
                .default_value(d.skips.same_light_tolerance as f64)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoolean::builder("skip-absent")
                .nick("Skip when nobody is there")
                .blurb("With face-tracking=false: pass frames through untouched while the model's presence stage sees nobody in the face region (the user walked away); a followed face needs no such check")
                .default_value(d.skips.skip_absent)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("presence-threshold")
                .nick("Presence threshold")
                .blurb("Probability of someone being in the face region below which nobody counts as there")
                .minimum(0.0)
                .maximum(1.0)
                .default_value(d.skips.presence_threshold as f64)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoolean::builder("qos")
                .nick("QoS")
                .blurb("In live pipelines, reuse the last relighting, without denoising, for frames that are late, or would be once processed (by what frames have cost lately, at most a frame's duration), instead of falling further behind, and post QoS messages")
                .default_value(DEFAULT_QOS)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoolean::builder("match-check")
                .nick("Monitor-match check")
                .blurb("Check that the light on the face follows the monitor stream (against replayed or synthesised faces, paper section 4.3): runs the light decoder on every relit frame and posts an element message lsydrelight-monitor-match about once a second with the score over match-window and its verdict")
                .default_value(d.match_check)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("match-window")
                .nick("Monitor-match window")
                .blurb("Seconds of frames the monitor-match score covers; shorter windows answer sooner and are less sure (README: the check's ROC by window length)")
                .minimum(0.5)
                .maximum(60.0)
                .default_value(d.matching.window)
                .mutable_playing()
                .build(),
            glib::ParamSpecDouble::builder("match-threshold")
                .nick("Monitor-match threshold")
                .blurb("Score (a correlation, -1 to 1) at or above which the face matches the monitor")
                .minimum(-1.0)
                .maximum(1.0)
                .default_value(d.matching.threshold)
                .mutable_playing()
                .build(),
            glib::ParamSpecBoxed::builder::<gst::Structure>("stats")
                .nick("Statistics")
                .blurb("Frames processed, relit, passed through and skipped (and why), source lights used, monitor fallbacks, resets, frames copied because upstream still held them, work done, and seconds spent: in all, in the network, cropping, pasting, copying, smoothing and reading monitor frames")
                .read_only()
                .build(),
        ]
    });
    PROPERTIES.as_ref()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_preset_overrides_an_environment_map_which_overrides_the_image() {
        let mut settings = Settings::default();
        assert_eq!(
            settings.target_source(),
            TargetSource::Image(settings.target_location.clone())
        );
        settings.target_environment = PathBuf::from("room.exr");
        settings.target_view.yaw = 30.0;
        let view = View {
            yaw: 30.0,
            ..View::default()
        };
        assert_eq!(
            settings.target_source(),
            TargetSource::Environment(PathBuf::from("room.exr"), view)
        );
        settings.target_preset = Preset::Candle;
        assert_eq!(
            settings.target_source(),
            TargetSource::Preset(Preset::Candle)
        );
    }

    #[test]
    fn the_presence_check_runs_only_for_a_fixed_region() {
        let mut settings = Settings::default();
        assert!(settings.skips.skip_absent && settings.face_tracking);
        assert!(
            !settings.policy_skips().skip_absent,
            "a followed face is the check"
        );
        settings.face_tracking = false;
        assert!(settings.policy_skips().skip_absent);
        settings.skips.skip_absent = false;
        assert!(
            !settings.policy_skips().skip_absent,
            "the user turned it off"
        );
    }
}
