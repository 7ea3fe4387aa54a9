//! The `lsydrelight` element's GObject and Aggregator glue: pads, start and
//! stop, events, queries and `aggregate`, which runs once per face frame.
//!
//! Each face frame takes its source light from the monitor stream
//! ([`super::monitor`]), goes through the per-frame policy
//! ([`crate::engine::policy`]), gets the policy's lighting change pasted on
//! ([`super::video`]) and its predicted light shown on `monitor_src`
//! ([`super::side_stream`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, LazyLock, Mutex};
use std::time::{Duration, Instant};

use gst::glib;
use gst::prelude::*;
use gst::subclass::prelude::*;
use gst_base::prelude::*;
use gst_base::subclass::prelude::*;

use super::match_check::{self, MatchCheck};
use super::monitor::{Decision, Fallback, MonitorTrack, Reading, Transition};
use super::qos::{self, Qos};
use super::region::FaceRegion;
use super::settings::{self, Settings};
use super::side_stream::{self, Queued, SideStream};
use super::stats::{Laps, Stats};
use super::target::{TargetSlot, Update};
use super::video::{
    self, caps_advice, face_size_problem, frame_duration, frame_view, is_gap, running_time,
    with_frame_mut,
};
use super::{ExecutionProvider, lock};
use crate::engine::{
    self, Action, FramePolicy, FrameRequest, PassThrough, Prepared, Provider, Relighter, Reuse,
    Source,
};
use crate::frame::{DetailDenoiser, FrameCopy, FrameMut};
use crate::light::Light;
use crate::targets::Crossfade;

pub static CAT: LazyLock<gst::DebugCategory> = LazyLock::new(|| {
    gst::DebugCategory::new(
        "lsydrelight",
        gst::DebugColorFlags::empty(),
        Some("Personalised face relighting"),
    )
});

/// Reference-timestamp caps of the meta that names the monitor frame used.
pub static MONITOR_TIMESTAMP_CAPS: LazyLock<gst::Caps> =
    LazyLock::new(|| gst::Caps::new_empty_simple("timestamp/x-lsydrelight-monitor"));

/// How often the element looks whether face frames wait for a silent monitor stream.
const MONITOR_WATCH_PERIOD: gst::ClockTime = gst::ClockTime::from_mseconds(200);

/// The face stream's state while the element runs.
struct State {
    policy: FramePolicy,
    region: FaceRegion,
    face_info: Option<gst_video::VideoInfo>,
    last_face_rt: Option<gst::ClockTime>,
    /// The target generation the policy has.
    target_generation: u64,
    /// The target light the policy is given, fading to a new one.
    fade: Crossfade,
    /// A NaN warning was posted and no frame has been relit since.
    nan_warned: bool,
    /// The camera's noise taken out of the face's detail (`denoise`).
    denoiser: DetailDenoiser,
    /// The frame's bytes as they came, while it is denoised beside the network.
    undenoised: FrameCopy,
}

pub struct LsydRelight {
    face_pad: gst_base::AggregatorPad,
    monitor_src: gst::Pad,
    monitor_pad: Mutex<Option<gst_base::AggregatorPad>>,
    /// The video target (`target_sink`), aligned like the monitor stream.
    target_pad: Mutex<Option<gst_base::AggregatorPad>>,
    target_track: Mutex<MonitorTrack>,
    side: Arc<SideStream>,
    settings: Mutex<Settings>,
    target: Mutex<TargetSlot>,
    /// The inference lock: held while a frame is processed.
    state: Mutex<Option<State>>,
    /// Kept after stop, so the last run's figures stay readable; reset at start.
    stats: Mutex<Stats>,
    monitor: Mutex<MonitorTrack>,
    qos: Qos,
    /// A warning about upstream's caps was posted (once per run).
    caps_warned: AtomicBool,
    /// A warning about dropped `monitor_src` frames was posted (once per run).
    side_drop_warned: AtomicBool,
    monitor_watch: Mutex<Option<gst::PeriodicClockId>>,
    match_check: Mutex<MatchCheck>,
}

impl State {
    /// Forgets the stream's past: temporal state, the followed face, the last
    /// frame's time. Returns whether there was temporal state to forget.
    fn reset(&mut self) -> bool {
        self.region.reset();
        self.denoiser.reset();
        self.last_face_rt = None;
        self.policy.reset()
    }
}

impl LsydRelight {
    /// The latency this element adds: the wait for monitor frames that lag the face
    /// (a negative `monitor-offset`) plus the time to relight a frame.
    fn report_latency(&self) {
        let (offset, processing) = {
            let s = lock(&self.settings);
            (s.monitor_offset, s.processing_latency)
        };
        let wait = gst::ClockTime::from_nseconds((-offset).max(0) as u64);
        gst::debug!(
            CAT,
            imp = self,
            "latency: monitor wait {wait}, processing {processing}"
        );
        self.obj().set_latency(wait + processing, None);
    }

    fn settings(&self) -> Settings {
        lock(&self.settings).clone()
    }

    fn monitor_pad(&self) -> Option<gst_base::AggregatorPad> {
        lock(&self.monitor_pad).clone()
    }

    fn count(&self, update: impl FnOnce(&mut Stats)) {
        update(&mut lock(&self.stats));
    }

    /// Sets a target property and resolves the target it names here, on the
    /// caller's thread (GstController's: the streaming thread).
    fn set_target(&self, name: &str, value: &glib::Value) {
        let source = {
            let mut settings = lock(&self.settings);
            settings.set(name, value);
            settings.target_source()
        };
        let decoded = TargetSlot::resolve(&self.target, &source);
        let update = lock(&self.target).update(decoded);
        match update {
            Update::Applied => gst::debug!(CAT, imp = self, "{name}: target {source}"),
            Update::Deferred => gst::debug!(
                CAT,
                imp = self,
                "target {source} cannot be read; the error surfaces at start"
            ),
            Update::KeptPrevious(e) => gst::element_imp_warning!(
                self,
                gst::ResourceError::OpenRead,
                ("Keeping the previous target light: {}", e),
                [
                    "Set target-location to a readable PNG image of monitor content, target-environment to a readable panorama, or target-preset to a preset."
                ]
            ),
        }
    }

    /// Forgets the face stream's temporal state: after flushes, seeks, caps changes
    /// and new segments. The monitor frame on screen stays: it is still on screen.
    fn reset_state(&self, why: &str) {
        if let Some(state) = lock(&self.state).as_mut() {
            state.reset();
        }
        lock(&self.match_check).reset();
        gst::debug!(CAT, imp = self, "reset temporal state: {why}");
    }

    /// The source light of the face frame at `face_rt`, and the running time of the
    /// monitor frame it came from; None to wait for more monitor data.
    fn source_light(
        &self,
        face_rt: Option<gst::ClockTime>,
        deadline: bool,
        settings: &Settings,
    ) -> Option<(Source, Option<i64>)> {
        let mut reading = Reading::default();
        // The pad slot before the track, as everywhere: never the other way round.
        let pad = self.monitor_pad();
        let mut track = lock(&self.monitor);
        let decision = match pad {
            Some(pad) => track.consume(
                &pad,
                face_rt,
                deadline,
                settings.monitor_offset,
                settings.monitor_timeout,
                &mut reading,
            ),
            None => Decision::Fallback(Fallback::NoMonitorPad),
        };
        self.count(|st| st.monitor.add(&reading));
        let (fallback, result) = match decision {
            Decision::Wait => {
                gst::trace!(
                    CAT,
                    imp = self,
                    "face frame at {}: waiting for monitor frames",
                    face_rt.display()
                );
                return None;
            }
            Decision::Known(light, at) => {
                gst::debug!(
                    CAT,
                    imp = self,
                    "face frame at {}: source light from the monitor frame shown at {} ({} consumed)",
                    face_rt.display(),
                    gst::ClockTime::from_nseconds(at.max(0) as u64),
                    reading.frames
                );
                (None, (Source::Known(light), Some(at)))
            }
            Decision::Fallback(f) => {
                gst::debug!(
                    CAT,
                    imp = self,
                    "face frame at {}: predicting the source light: {}",
                    face_rt.display(),
                    f.describe()
                );
                (Some(f), (Source::Unknown, None))
            }
        };
        let transition = track.note_fallback(fallback);
        drop(track);
        match transition {
            Some(Transition::FallbackStarted(f)) => {
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
            Some(Transition::Returned) => gst::element_imp_info!(
                self,
                gst::StreamError::Failed,
                ("The monitor stream is back: relighting with the monitor's light again")
            ),
            None => {}
        }
        Some(result)
    }

    /// The monitor-stream track of a sink pad that is not the face pad.
    fn track_of(&self, pad: &gst_base::AggregatorPad) -> &Mutex<MonitorTrack> {
        if lock(&self.target_pad).as_ref() == Some(pad) {
            &self.target_track
        } else {
            &self.monitor
        }
    }

    /// The video target's light for the face frame at `face_rt`, aligned by running
    /// time as the monitor stream is: Some(None) keeps the target in use (no video
    /// target, or it has not started, stalled or ended); None waits for more data.
    fn video_target(
        &self,
        face_rt: Option<gst::ClockTime>,
        deadline: bool,
        settings: &Settings,
    ) -> Option<Option<Light>> {
        let Some(pad) = lock(&self.target_pad).clone() else {
            return Some(None);
        };
        let mut reading = Reading::default();
        let mut track = lock(&self.target_track);
        let decision = track.consume(
            &pad,
            face_rt,
            deadline,
            0,
            settings.monitor_timeout,
            &mut reading,
        );
        self.count(|st| st.target_stream.add(&reading));
        let (light, fallback) = match decision {
            Decision::Wait => return None,
            Decision::Known(light, _) => (Some(light), None),
            Decision::Fallback(f) => (None, Some(f)),
        };
        let transition = track.note_fallback(fallback);
        drop(track);
        match transition {
            Some(Transition::FallbackStarted(f)) if f != Fallback::NotStarted => {
                gst::element_imp_warning!(
                    self,
                    gst::StreamError::Failed,
                    (
                        "Keeping the last target light: {}",
                        f.describe().replace("monitor", "target")
                    ),
                    ["Relighting follows the target stream again as soon as it sends frames."]
                )
            }
            Some(Transition::Returned) => {
                gst::debug!(CAT, imp = self, "the target stream is back")
            }
            _ => gst::trace!(CAT, imp = self, "video target at {}", face_rt.display()),
        }
        Some(light)
    }

    /// Brings the policy up to date for the next frame: resets after a break in the
    /// stream, new settings, a new target.
    fn update_state(
        &self,
        state: &mut State,
        buffer: &gst::Buffer,
        settings: &Settings,
        video_target: Option<Light>,
    ) {
        let rt = running_time(&self.face_pad, buffer.pts());
        // A slow stream (1 fps) is not a broken one: a gap counts only beyond a few frames.
        let frame = buffer
            .duration()
            .or_else(|| state.face_info.as_ref().and_then(frame_duration))
            .unwrap_or(gst::ClockTime::ZERO);
        let gap_limit = settings.reset_gap.max(3 * frame);
        let gap = match (state.last_face_rt, rt) {
            (Some(a), Some(b)) => a.nseconds().abs_diff(b.nseconds()) > gap_limit.nseconds(),
            _ => false,
        };
        let discont = buffer.flags().contains(gst::BufferFlags::DISCONT);
        if (discont || gap) && state.reset() {
            gst::debug!(
                CAT,
                imp = self,
                "reset temporal state: {} before the frame at {}",
                if discont { "a discontinuity" } else { "a gap" },
                rt.display()
            );
        }
        state.last_face_rt = rt.or(state.last_face_rt);
        state.policy.set_temporal(settings.temporal);
        state.policy.set_skips(settings.policy_skips());
        let newer = lock(&self.target).newer_than(state.target_generation);
        if let Some((light, generation)) = newer {
            gst::info!(
                CAT,
                imp = self,
                "target light now {}, fading in over {}",
                settings.target_source(),
                settings.target_transition
            );
            state
                .fade
                .retarget((*light).clone(), settings.target_transition.nseconds());
            state.target_generation = generation;
        }
        if let Some(light) = video_target {
            // A video follows its frames: each is the target at once.
            state.fade.jump(light);
        }
        self.follow_fade(state, rt);
    }

    /// Gives the policy the target light of the frame at `rt`, mid-fade a blend.
    fn follow_fade(&self, state: &mut State, rt: Option<gst::ClockTime>) {
        let Some(light) = state.fade.at(rt.map(|t| t.nseconds())) else {
            return;
        };
        if state.policy.target() == Some(light) {
            return;
        }
        let light = light.clone();
        let encoding = Instant::now();
        let encoded = state.policy.set_target(&light);
        let seconds = encoding.elapsed().as_secs_f64();
        self.count(|st| st.target_seconds += seconds);
        if let Err(e) = encoded {
            gst::element_imp_warning!(
                self,
                gst::LibraryError::Failed,
                (
                    "Keeping the previous target light: cannot encode the new one: {}",
                    e
                )
            );
            if let Some(kept) = state.policy.target().cloned() {
                state.fade.jump(kept);
            }
        }
    }

    /// Applies GstController values (target-yaw and the like) at the face frame's stream time.
    fn sync_controlled(&self, face: &gst::Buffer) {
        let segment = self.face_pad.segment();
        let stream_time = segment
            .downcast_ref::<gst::ClockTime>()
            .and_then(|seg| seg.to_stream_time(face.pts()));
        if let Some(t) = stream_time
            && self.obj().has_active_control_bindings()
        {
            let _ = self.obj().sync_values(t);
        }
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
        video_target: Option<Light>,
        late: bool,
        settings: &Settings,
    ) -> Result<gst::Buffer, gst::FlowError> {
        let started = Instant::now();
        let mut laps = Laps::start();
        let screen = match &source {
            Source::Known(light) if settings.match_check => Some(light.clone()),
            _ => None,
        };
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
        self.update_state(state, &buffer, settings, video_target);
        // The prediction shows a blurred view of the user's screen: it is made only
        // for someone who asked for it (or when it is the only source light there is).
        let show_prediction = self.monitor_src.is_linked();
        let want_prediction = show_prediction || settings.match_check;
        let time = running_time(&self.face_pad, buffer.pts()).map_or(0.0, |t| t.seconds_f64());
        let (region, prepared, setup_seconds, prepare_seconds) = {
            let frame = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer.as_ref(), &info)
                .map_err(|_| gst::FlowError::Error)?;
            let view = frame_view(&frame).ok_or(gst::FlowError::NotNegotiated)?;
            let setup_seconds = laps.lap();
            let region = state
                .region
                .locate(&view, time, settings)
                .map_err(|e| self.engine_failed(e))?;
            if let Some(face) = region.detected {
                gst::debug!(
                    CAT,
                    imp = self,
                    "face at ({:.0}, {:.0}), {:.0} px high, score {:.2}",
                    face.cx,
                    face.cy,
                    face.height,
                    face.score
                );
            }
            laps.lap();
            let prepared = state
                .policy
                .prepare(FrameRequest {
                    frame: &view,
                    crop: region.crop,
                    strength: region.strength,
                    source,
                    late,
                    want_prediction,
                })
                .map_err(|e| self.engine_failed(e))?;
            (region, prepared, setup_seconds, laps.lap())
        };
        let crop = region.crop;
        let feather = (settings.feather * crop.size as f64).round() as usize;
        let State {
            policy,
            denoiser,
            undenoised,
            ..
        } = state;
        // Seconds the frame waited for the denoising and pasting; the
        // denoising's own; with the network, seconds in the policy.
        let (mut paste_seconds, mut denoise_seconds, mut finish_seconds) = (0.0, 0.0, 0.0);
        // What copying the frame to write it took, where upstream still held it.
        let mut copied = None;
        let strength = region.strength;
        let mut denoise = |fm: &mut FrameMut| {
            let denoising = Instant::now();
            if settings.denoise {
                denoiser.apply(fm, crop, feather, strength);
            }
            denoising.elapsed().as_secs_f64()
        };
        let outcome = match prepared {
            Prepared::Decided(decided) => {
                let outcome = policy.decided(decided);
                if let Some(change) = outcome.change {
                    let (mut frame, copy) = self.map_writable(&mut buffer, &info)?;
                    copied = copy;
                    // A late frame is to catch up: it costs the paste alone.
                    let late = outcome.action == Action::Reused(Reuse::Late);
                    if late && settings.denoise {
                        gst::debug!(CAT, imp = self, "late: not denoised, to catch up");
                    }
                    with_frame_mut(&mut frame, |fm| {
                        if !late {
                            denoise_seconds = denoise(fm);
                            paste_seconds += denoise_seconds;
                        }
                        let pasting = Instant::now();
                        change.apply_faded(fm, crop, feather, outcome.strength);
                        paste_seconds += pasting.elapsed().as_secs_f64();
                    })
                    .ok_or(gst::FlowError::NotNegotiated)?;
                }
                outcome
            }
            Prepared::Relight(pending) => {
                let (mut frame, copy) = self.map_writable(&mut buffer, &info)?;
                copied = copy;
                with_frame_mut(&mut frame, |fm| {
                    let finishing = Instant::now();
                    // The denoising needs the frame and the crop alone: it runs
                    // on the other core while the network runs on this one.
                    let outcome = if settings.denoise {
                        // The copy to undo it by is made there too.
                        let (outcome, denoising, waited) = policy.finish_while(pending, || {
                            undenoised.save(fm);
                            denoise(fm)
                        });
                        (denoise_seconds, paste_seconds) = (denoising, waited);
                        finish_seconds -= waited;
                        let outcome = outcome?;
                        if outcome.change.is_none() {
                            gst::debug!(
                                CAT,
                                imp = self,
                                "undoing the denoising: no change to paste"
                            );
                            undenoised.restore(fm);
                        }
                        outcome
                    } else {
                        policy.finish(pending)?
                    };
                    finish_seconds += finishing.elapsed().as_secs_f64();
                    if let Some(change) = outcome.change {
                        let pasting = Instant::now();
                        change.apply_faded(fm, crop, feather, outcome.strength);
                        paste_seconds += pasting.elapsed().as_secs_f64();
                    }
                    Ok(outcome)
                })
                .ok_or(gst::FlowError::NotNegotiated)?
                .map_err(|e| self.engine_failed(e))?
            }
        };
        let policy_seconds = prepare_seconds + finish_seconds;
        gst::debug!(
            CAT,
            imp = self,
            "frame at {}: {outcome}",
            buffer.pts().display()
        );
        self.count(|st| {
            st.paste_seconds += paste_seconds;
            st.denoise_seconds += denoise_seconds;
            if let Some(copy) = copied {
                st.frames_copied += 1;
                st.copy_seconds += copy.as_secs_f64();
            }
        });
        laps.lap();
        let outcome_shows_face = outcome.change.is_some();
        let shown_strength = outcome.strength;
        // The next denoised frame must not be filtered against one that was not.
        if (!outcome_shows_face || !settings.denoise) && denoiser.reset() {
            gst::debug!(
                CAT,
                imp = self,
                "denoising starts afresh: the frame at {} was not denoised",
                buffer.pts().display()
            );
        }
        let predicted = outcome.predicted;
        let warn_nan = match outcome.action {
            Action::PassedThrough(PassThrough::NonFinite) => {
                !std::mem::replace(&mut state.nan_warned, true)
            }
            Action::Relit => {
                state.nan_warned = false;
                false
            }
            _ => false,
        };
        let policy_counts = policy.counts();
        let follow_counts = state.region.counts();
        drop(guard);
        if outcome_shows_face {
            // Downstream (and the measures) can see which square was relit,
            // how strongly, and how far the change reaches beyond it.
            let mut roi = gst_video::VideoRegionOfInterestMeta::add(
                buffer.make_mut(),
                "face",
                (
                    crop.x as u32,
                    crop.y as u32,
                    crop.size as u32,
                    crop.size as u32,
                ),
            );
            roi.add_param(
                gst::Structure::builder("lsydrelight")
                    .field("strength", f64::from(shown_strength))
                    .field("feather", feather as u32)
                    .build(),
            );
        }
        if warn_nan {
            gst::element_imp_warning!(
                self,
                gst::StreamError::Decode,
                ("The model produced NaN or Inf; passing frames through unchanged until it recovers"),
                ["The engine restarts its temporal state and relights the next frame afresh."]
            );
        }
        let processing_seconds = started.elapsed().as_secs_f64();
        let finish_seconds = laps.lap();
        self.count(|st| {
            st.processing_seconds += processing_seconds;
            st.stages.setup += setup_seconds;
            st.stages.policy += policy_seconds;
            st.stages.finish += finish_seconds;
            st.policy = policy_counts;
            st.face_detections = follow_counts.detections;
            st.face_seconds = follow_counts.seconds;
        });
        if show_prediction {
            self.show_prediction(predicted.as_ref(), &buffer);
        }
        if settings.match_check {
            let fps = info.fps();
            let fps = if fps.numer() > 0 {
                fps.numer() as f64 / fps.denom() as f64
            } else {
                30.0
            };
            self.check_match(time, screen.zip(predicted), fps, settings);
        }
        Ok(buffer)
    }

    /// Maps the face buffer for writing. Where upstream still holds the buffer
    /// or its memory (a `tee` before the element, an `appsrc` pushing frames
    /// it keeps), GStreamer first copies the whole frame, so that the holder's
    /// stays as it was: a few milliseconds a frame at 2160p, returned here for
    /// `stats` (`frames-copied`, `copy-seconds`).
    fn map_writable<'a>(
        &self,
        buffer: &'a mut gst::Buffer,
        info: &gst_video::VideoInfo,
    ) -> Result<
        (
            gst_video::VideoFrameRef<&'a mut gst::BufferRef>,
            Option<Duration>,
        ),
        gst::FlowError,
    > {
        let held_upstream = !buffer.is_writable() || !buffer.is_all_memory_writable();
        let mapping = Instant::now();
        let frame = gst_video::VideoFrameRef::from_buffer_ref_writable(buffer.make_mut(), info)
            .map_err(|_| gst::FlowError::Error)?;
        let copied = held_upstream.then(|| mapping.elapsed());
        if let Some(copy) = copied {
            gst::debug!(
                CAT,
                imp = self,
                "the face buffer is still held upstream: copied to be written ({:.2} ms)",
                copy.as_secs_f64() * 1e3
            );
        }
        Ok((frame, copied))
    }

    /// Adds a face frame to the monitor-match check, and posts its message when due.
    fn check_match(&self, time: f64, pair: Option<(Light, Light)>, fps: f64, settings: &Settings) {
        let pair = pair.as_ref().map(|(screen, predicted)| (screen, predicted));
        let Some(score) = lock(&self.match_check).frame(time, pair, &settings.matching, fps) else {
            return;
        };
        gst::debug!(
            CAT,
            imp = self,
            "monitor match at {time:.2} s: {} over {} frames, score {:?}, components {:?}",
            score.verdict.name(),
            score.frames,
            score.score,
            score.components
        );
        let structure = match_check::message_structure(
            &score,
            &settings.matching,
            gst::ClockTime::from_seconds_f64(time),
        );
        let element = self.obj();
        let _ = element.post_message(
            gst::message::Element::builder(structure)
                .src(&*element)
                .build(),
        );
    }

    /// Queues the predicted light (or a gap) for `monitor_src` at the face frame's time.
    fn show_prediction(&self, light: Option<&Light>, face: &gst::Buffer) {
        self.side.start(&self.face_pad.segment());
        // A non-live pipeline waits for a slow side branch rather than lose its frames.
        let wait = !self.qos.is_live();
        let queued = self
            .side
            .push_frame(light, face.pts(), face.duration(), wait);
        if light.is_some() {
            self.count(|st| {
                st.monitor_out += 1;
                if queued == Queued::DroppedOldest {
                    st.monitor_dropped += 1;
                }
            });
        }
        if queued == Queued::DroppedOldest {
            gst::debug!(
                CAT,
                imp = self,
                "monitor_src is behind: dropped its oldest frame"
            );
            if !self.side_drop_warned.swap(true, Ordering::Relaxed) {
                gst::element_imp_warning!(
                    self,
                    gst::StreamError::Failed,
                    ("monitor_src falls behind the live face stream: dropping its oldest frames"),
                    [
                        "The branch after monitor_src consumes slower than the face frame rate; give it a leaky queue or a faster sink. stats' monitor-dropped counts them."
                    ]
                );
            }
        }
    }

    /// In a non-live pipeline the aggregator waits for data on every pad, so a
    /// monitor branch that never produces would hold the face stream forever with
    /// no word. Run every `MONITOR_WATCH_PERIOD` from the system clock.
    fn watch_monitor(&self) {
        if self.qos.is_live() {
            return;
        }
        let Some(pad) = self.monitor_pad() else {
            return;
        };
        let timeout = Duration::from_nanos(lock(&self.settings).monitor_timeout.nseconds());
        let waiting = self.face_pad.has_buffer() && !pad.has_buffer() && !pad.is_eos();
        let mut track = lock(&self.monitor);
        if !waiting {
            track.flowing();
            return;
        }
        if track.newly_starved(timeout) {
            drop(track);
            gst::warning!(
                CAT,
                imp = self,
                "face frames wait for a silent monitor stream"
            );
            gst::element_imp_warning!(
                self,
                gst::StreamError::Failed,
                (
                    "Face frames are waiting for the monitor stream: monitor_sink has received nothing for {:.1} s",
                    timeout.as_secs_f64()
                ),
                [
                    "In a non-live pipeline lsydrelight waits for the monitor frame that lit each face frame. Check that the branch into monitor_sink produces frames (or ends with EOS), or release monitor_sink to relight with the predicted light."
                ]
            );
        }
    }

    fn start_monitor_watch(&self) {
        let clock = gst::SystemClock::obtain();
        let id = clock.new_periodic_id(clock.time(), MONITOR_WATCH_PERIOD);
        let element = self.obj().downgrade();
        let scheduled = id.wait_async(move |_, _, _| {
            if let Some(element) = element.upgrade() {
                element.imp().watch_monitor();
            }
        });
        match scheduled {
            Ok(_) => *lock(&self.monitor_watch) = Some(id),
            Err(e) => gst::warning!(CAT, imp = self, "cannot watch the monitor stream: {e:?}"),
        }
    }

    fn stop_monitor_watch(&self) {
        if let Some(id) = lock(&self.monitor_watch).take() {
            id.unschedule();
        }
    }

    /// Sends a gap on the face stream downstream, and to `monitor_src`. Before the
    /// first frame (or after a flush) downstream has no segment yet, and a gap may
    /// not precede it: that gap is dropped.
    fn forward_gap(&self, gap: &gst::Buffer) {
        let src = self.obj().src_pad().clone();
        if let Some(pts) = gap.pts()
            && src.sticky_event::<gst::event::Segment>(0).is_some()
        {
            let event = || {
                gst::event::Gap::builder(pts)
                    .duration(gap.duration())
                    .build()
            };
            gst::debug!(CAT, imp = self, "gap at {pts} passed on");
            src.push_event(event());
            if self.monitor_src.is_linked() {
                self.side.push_event(event());
            }
        }
    }

    /// The policy with the model's network, and the face region (with the face
    /// detector when the face is followed).
    fn start_engine(
        &self,
        settings: &Settings,
    ) -> Result<(FramePolicy, FaceRegion), gst::ErrorMessage> {
        let env = engine::environment(&settings.ort_library)
            .map_err(|e| gst::error_msg!(gst::LibraryError::Init, ["{}", e]))?;
        let provider = match settings.provider {
            ExecutionProvider::Cpu => Provider::Cpu,
            ExecutionProvider::Cuda => Provider::Cuda,
        };
        let relighter = Relighter::new(
            env,
            &settings.model_location,
            settings.threads as usize,
            provider,
        )
        .map_err(|e| match e {
            engine::EngineError::Provider(_) => {
                gst::error_msg!(gst::LibraryError::Init, ["{}", e])
            }
            engine::EngineError::Model(engine::ContractError::Missing(_)) => {
                gst::error_msg!(gst::ResourceError::NotFound, ["{}", e])
            }
            _ => gst::error_msg!(gst::ResourceError::OpenRead, ["{}", e]),
        })?;
        gst::info!(
            CAT,
            imp = self,
            "loaded model {} ({}x{}, {}) with ONNX Runtime {}",
            relighter.manifest().name,
            relighter.resolution(),
            relighter.resolution(),
            relighter.manifest().precision,
            settings.ort_library.display()
        );
        let region = FaceRegion::new(env, settings, relighter.manifest().crop).map_err(|e| {
            gst::error_msg!(
                gst::ResourceError::OpenRead,
                [
                    "{}; or set face-tracking=false to relight a fixed region",
                    e
                ]
            )
        })?;
        let policy = FramePolicy::new(relighter, settings.temporal, settings.policy_skips());
        Ok((policy, region))
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
                            gst::PadMode::Push => imp
                                .side
                                .activate(pad, active)
                                .map_err(|e| gst::loggable_error!(CAT, "monitor_src task: {e}")),
                            _ => Err(gst::loggable_error!(CAT, "monitor_src only pushes")),
                        },
                    )
                })
                .query_function(|pad, parent, query| {
                    LsydRelight::catch_panic_pad_function(
                        parent,
                        || false,
                        |imp| match query.view_mut() {
                            // Answered from the side stream, never waiting for a frame
                            // that is being relit.
                            gst::QueryViewMut::Caps(q) => {
                                let caps = imp
                                    .side
                                    .current_caps()
                                    .unwrap_or_else(|| pad.pad_template_caps());
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
            target_pad: Mutex::new(None),
            target_track: Mutex::new(MonitorTrack::default()),
            side: Arc::new(SideStream::default()),
            settings: Mutex::new(Settings::default()),
            target: Mutex::new(TargetSlot::default()),
            state: Mutex::new(None),
            stats: Mutex::new(Stats::default()),
            monitor: Mutex::new(MonitorTrack::default()),
            qos: Qos::default(),
            caps_warned: AtomicBool::new(false),
            side_drop_warned: AtomicBool::new(false),
            monitor_watch: Mutex::new(None),
            match_check: Mutex::new(MatchCheck::default()),
        }
    }
}

impl ObjectImpl for LsydRelight {
    fn properties() -> &'static [glib::ParamSpec] {
        settings::properties()
    }

    fn set_property(&self, _id: usize, value: &glib::Value, pspec: &glib::ParamSpec) {
        match pspec.name() {
            name @ ("target-location" | "target-preset" | "target-environment" | "target-fov"
            | "target-yaw" | "target-pitch" | "target-exposure") => self.set_target(name, value),
            "monitor-offset" | "processing-latency" => {
                lock(&self.settings).set(pspec.name(), value);
                self.report_latency();
            }
            name => {
                let known = lock(&self.settings).set(name, value);
                debug_assert!(known, "property {name} is a setting");
            }
        }
    }

    fn property(&self, _id: usize, pspec: &glib::ParamSpec) -> glib::Value {
        match pspec.name() {
            "stats" => lock(&self.stats).to_structure().to_value(),
            name => lock(&self.settings)
                .get(name)
                .unwrap_or_else(|| panic!("property {name} is a setting")),
        }
    }

    fn constructed(&self) {
        self.parent_constructed();
        let obj = self.obj();
        obj.add_pad(&self.face_pad).expect("add sink pad");
        obj.add_pad(&self.monitor_src).expect("add monitor_src pad");
        self.report_latency();
    }

    fn dispose(&self) {
        self.stop_monitor_watch();
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
            let agg = gst_base::AggregatorPad::static_type();
            let face = video::face_caps();
            vec![
                gst::PadTemplate::with_gtype(
                    "sink",
                    gst::PadDirection::Sink,
                    gst::PadPresence::Always,
                    &face,
                    agg,
                )
                .expect("sink template"),
                gst::PadTemplate::with_gtype(
                    "monitor_sink",
                    gst::PadDirection::Sink,
                    gst::PadPresence::Request,
                    &video::monitor_caps(),
                    agg,
                )
                .expect("monitor_sink template"),
                gst::PadTemplate::with_gtype(
                    "target_sink",
                    gst::PadDirection::Sink,
                    gst::PadPresence::Request,
                    &video::monitor_caps(),
                    agg,
                )
                .expect("target_sink template"),
                gst::PadTemplate::with_gtype(
                    "src",
                    gst::PadDirection::Src,
                    gst::PadPresence::Always,
                    &face,
                    agg,
                )
                .expect("src template"),
                gst::PadTemplate::new(
                    "monitor_src",
                    gst::PadDirection::Src,
                    gst::PadPresence::Always,
                    &side_stream::template_caps(),
                )
                .expect("monitor_src template"),
            ]
        });
        TEMPLATES.as_ref()
    }

    fn release_pad(&self, pad: &gst::Pad) {
        let mut tp = lock(&self.target_pad);
        if tp
            .as_ref()
            .is_some_and(|p| p.upcast_ref::<gst::Pad>() == pad)
        {
            *tp = None;
            drop(tp);
            *lock(&self.target_track) = MonitorTrack::default();
            gst::debug!(CAT, imp = self, "target_sink released");
            self.parent_release_pad(pad);
            return;
        }
        drop(tp);
        let mut mp = lock(&self.monitor_pad);
        if mp
            .as_ref()
            .is_some_and(|p| p.upcast_ref::<gst::Pad>() == pad)
        {
            *mp = None;
            drop(mp);
            *lock(&self.monitor) = MonitorTrack::default();
            gst::debug!(CAT, imp = self, "monitor_sink released");
        } else {
            drop(mp);
        }
        self.parent_release_pad(pad);
    }
}

impl AggregatorImpl for LsydRelight {
    fn start(&self) -> Result<(), gst::ErrorMessage> {
        let settings = self.settings();
        let (mut policy, region) = self.start_engine(&settings)?;
        let (target, target_generation) =
            TargetSlot::start(&self.target, &settings.target_source()).map_err(|e| {
                gst::error_msg!(
                    gst::ResourceError::NotFound,
                    ["{}; set target-location to a PNG image of monitor content (shipped ones are in models/targets), target-environment to a panorama, or target-preset", e]
                )
            })?;
        policy.set_target(&target).map_err(|e| {
            gst::error_msg!(
                gst::LibraryError::Failed,
                ["cannot encode the target light: {}", e]
            )
        })?;
        let mut fade = Crossfade::default();
        fade.jump((*target).clone());
        *lock(&self.state) = Some(State {
            policy,
            region,
            face_info: None,
            last_face_rt: None,
            target_generation,
            fade,
            nan_warned: false,
            denoiser: DetailDenoiser::default(),
            undenoised: FrameCopy::default(),
        });
        *lock(&self.stats) = Stats::default();
        lock(&self.monitor).restart();
        lock(&self.target_track).restart();
        self.caps_warned.store(false, Ordering::Relaxed);
        self.side_drop_warned.store(false, Ordering::Relaxed);
        self.start_monitor_watch();
        Ok(())
    }

    fn stop(&self) -> Result<(), gst::ErrorMessage> {
        self.stop_monitor_watch();
        lock(&self.target).stop();
        self.qos.reset();
        *lock(&self.state) = None;
        lock(&self.monitor).stop();
        lock(&self.target_track).stop();
        self.side.clear();
        Ok(())
    }

    fn src_activate(&self, mode: gst::PadMode, active: bool) -> Result<(), gst::LoggableError> {
        if !active {
            // The aggregating thread may wait for room on monitor_src; stopping the
            // src pad's task waits for that thread.
            self.side.set_flushing(true);
        }
        self.parent_src_activate(mode, active)
    }

    fn create_new_pad(
        &self,
        templ: &gst::PadTemplate,
        _req_name: Option<&str>,
        _caps: Option<&gst::Caps>,
    ) -> Option<gst_base::AggregatorPad> {
        let name = templ.name_template();
        let (slot, track) = match name {
            "monitor_sink" => (&self.monitor_pad, &self.monitor),
            "target_sink" => (&self.target_pad, &self.target_track),
            _ => return None,
        };
        let mut held = lock(slot);
        if held.is_some() {
            gst::warning!(CAT, imp = self, "only one {name} pad");
            return None;
        }
        let pad = gst::PadBuilder::<gst_base::AggregatorPad>::from_template(templ)
            .name(name)
            .build();
        *held = Some(pad.clone());
        drop(held);
        lock(track).attach(&pad);
        gst::debug!(CAT, imp = self, "{name} requested");
        Some(pad)
    }

    fn sink_event(&self, pad: &gst_base::AggregatorPad, event: gst::Event) -> bool {
        use gst::EventView;
        let is_face = pad == &self.face_pad;
        match event.view() {
            EventView::StreamStart(e) if is_face => {
                self.side.set_face_stream_id(e.stream_id());
                self.reset_state("new stream");
            }
            EventView::Caps(c) => {
                let Ok(info) = gst_video::VideoInfo::from_caps(c.caps()) else {
                    gst::element_imp_error!(
                        self,
                        gst::StreamError::Format,
                        ("Cannot read the caps {}", c.caps()),
                        ["{}", caps_advice(pad.name().as_str())]
                    );
                    return false;
                };
                if !is_face {
                    gst::debug!(CAT, imp = self, "{} caps {}", pad.name(), c.caps());
                    lock(self.track_of(pad)).set_info(info);
                    return self.parent_sink_event(pad, event);
                }
                if let Some(problem) = face_size_problem(&info) {
                    gst::element_imp_error!(
                        self,
                        gst::StreamError::Format,
                        ("{}", problem),
                        ["{}", caps_advice("sink")]
                    );
                    return false;
                }
                let changed = lock(&self.state).as_mut().is_some_and(|state| {
                    let changed = state.face_info.as_ref() != Some(&info);
                    state.face_info = Some(info.clone());
                    changed
                });
                self.side.set_fps(info.fps());
                if changed {
                    self.reset_state("caps changed");
                    self.qos.forget_cost();
                    self.obj().src_pad().mark_reconfigure();
                }
            }
            EventView::Segment(e) if is_face => {
                let segment = e.segment().clone();
                if let Some(seg) = segment.downcast_ref::<gst::ClockTime>() {
                    self.obj().update_segment(seg);
                }
                self.side.push_event(gst::event::Segment::new(&segment));
                self.reset_state("new segment");
            }
            EventView::FlushStart(_) if is_face => {
                self.side.set_flushing(true);
                self.monitor_src.push_event(gst::event::FlushStart::new());
            }
            EventView::FlushStop(_) if is_face => {
                // The task pauses itself when it sees the flush; holding its stream lock
                // waits for that iteration to end, so the pause cannot land after the
                // restart below, and no buffer from before the flush follows it.
                self.side.set_flushing(true);
                let _task = self.monitor_src.stream_lock();
                self.monitor_src
                    .push_event(gst::event::FlushStop::new(true));
                self.side.reset();
                if self.monitor_src.is_active()
                    && let Err(e) = self.side.activate(&self.monitor_src, true)
                {
                    gst::warning!(CAT, imp = self, "cannot restart monitor_src: {e}");
                }
                self.qos.reset();
                self.reset_state("flush");
            }
            EventView::FlushStop(_) => {
                lock(self.track_of(pad)).flush();
            }
            _ => {}
        }
        self.parent_sink_event(pad, event)
    }

    fn sink_query(&self, pad: &gst_base::AggregatorPad, query: &mut gst::QueryRef) -> bool {
        let is_face = pad == &self.face_pad;
        let templ = if is_face {
            video::face_caps()
        } else {
            video::monitor_caps()
        };
        match query.view_mut() {
            // The face and relit video have the same caps: ask downstream.
            gst::QueryViewMut::Caps(q) if is_face => {
                let downstream = self.obj().src_pad().peer_query_caps(Some(&templ));
                if let Some(f) = q.filter()
                    && !f.can_intersect(&templ)
                    && !self.caps_warned.swap(true, Ordering::Relaxed)
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
            let live = q.result().0;
            gst::debug!(
                CAT,
                imp = self,
                "upstream is {}",
                if live { "live" } else { "not live" }
            );
            self.qos.set_live(live);
        }
        handled
    }

    fn src_event(&self, event: gst::Event) -> bool {
        if let gst::EventView::Qos(q) = event.view() {
            self.qos.on_event(q);
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
                gst::debug!(CAT, imp = self, "face stream ended");
                self.side.push_eos(&self.face_pad.segment());
                return Err(gst::FlowError::Eos);
            }
            return Err(gst_base::AGGREGATOR_FLOW_NEED_DATA);
        };
        if is_gap(&face) {
            self.face_pad.drop_buffer();
            self.forward_gap(&face);
            return Ok(gst::FlowSuccess::Ok);
        }
        let started = Instant::now();
        self.sync_controlled(&face);
        let settings = self.settings();
        let face_rt = running_time(&self.face_pad, face.pts());
        let Some((source, monitor_rt)) = self.source_light(face_rt, timeout, &settings) else {
            return Err(gst_base::AGGREGATOR_FLOW_NEED_DATA);
        };
        let Some(video_target) = self.video_target(face_rt, timeout, &settings) else {
            return Err(gst_base::AGGREGATOR_FLOW_NEED_DATA);
        };
        // The peeked reference goes first: a buffer held twice is copied to be
        // written (`map_writable`), a whole frame's copy on every frame.
        drop(face);
        let buffer = self
            .face_pad
            .pop_buffer()
            .ok_or(gst_base::AGGREGATOR_FLOW_NEED_DATA)?;
        let element = self.obj();
        let late = settings.qos
            && self
                .qos
                .is_late(element.upcast_ref(), face_rt, buffer.duration());
        let mut out = self.process_frame(buffer, source, video_target, late, &settings)?;
        if late {
            let (relit, reused) = {
                let st = lock(&self.stats);
                (st.frames - st.policy.reused_late, st.policy.reused_late)
            };
            let msg = qos::late_message(
                element.upcast_ref(),
                &self.face_pad.segment(),
                &out,
                face_rt,
                relit,
                reused,
            );
            let _ = element.post_message(msg);
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
        let frame_time = started.elapsed();
        if !late {
            self.qos.record_full_cost(frame_time);
        }
        let frame_seconds = frame_time.as_secs_f64();
        self.count(|st| st.stages.frame += frame_seconds);
        element.finish_buffer(out)
    }
}
