//! Relighting one face frame: the face region is found, the per-frame policy
//! decides or runs the network, and the frame is mapped for writing, denoised
//! and gets the lighting change pasted on; then the frame's `face` region meta,
//! its figures in `stats`, its predicted light for `monitor_src` and the
//! monitor-match check.

use std::time::{Duration, Instant};

use gst::prelude::*;
use gst::subclass::prelude::*;

use super::imp::{CAT, LsydRelight};
use super::lock;
use super::settings::Settings;
use super::state::State;
use super::stats::Laps;
use super::video::{frame_view, running_time, with_frame_mut};
use crate::engine::{self, Action, FrameRequest, PassThrough, Prepared, Reuse, Source};
use crate::frame::FrameMut;
use crate::light::Light;

impl LsydRelight {
    /// After a frame not found late: drops the denoising for the rest of a
    /// live stream whose frames cannot afford it ([`super::qos::Qos::drops_denoising`]),
    /// and says so.
    pub(super) fn judge_denoising(&self, settings: &Settings, duration: Option<gst::ClockTime>) {
        if !(settings.denoise && settings.qos) {
            return;
        }
        let Some(cost) = self.qos.drops_denoising(duration) else {
            return;
        };
        gst::info!(
            CAT,
            imp = self,
            "frames cost {cost:?} at the median: denoising dropped"
        );
        self.count(|st| st.denoising_dropped = true);
        gst::element_imp_warning!(
            self,
            gst::CoreError::Clock,
            (
                "Frames take {:.1} ms at the median, more than their period: the denoising is off for this stream to keep real time",
                cost.as_secs_f64() * 1e3
            ),
            [
                "Set denoise=false to start without it, ask the camera for a smaller size, or free the CPU; new caps try it again."
            ]
        );
    }

    pub(super) fn engine_failed(&self, e: engine::EngineError) -> gst::FlowError {
        gst::element_imp_error!(self, gst::StreamError::Failed, ("Relighting failed: {}", e));
        gst::FlowError::Error
    }

    /// Relights one face buffer in place (a copy, when upstream still holds it).
    /// `late` says the frame is already behind its deadline (QoS).
    pub(super) fn process_frame(
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
            if let Some(step) = region.search.filter(|s| s.near || s.tiles > 0) {
                gst::debug!(
                    CAT,
                    imp = self,
                    "face search: whole frame {}, closer look round a small face {}, {} tiles of the scan; \
                     the small face boxed by the whole frame, which scored it higher: {}",
                    step.whole_frame,
                    step.near,
                    step.tiles,
                    step.whole_frame_box
                );
            }
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
                    face: region.face,
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
            // how strongly, how far the change reaches beyond it, and where
            // the face is in it (one face height square about its centre).
            let side = crop.size as f32;
            let face_size = region.face.height * side;
            let face_corner = |start: usize, centre: f32| {
                (start as f32 + centre * side - face_size / 2.0).round() as i32
            };
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
                    .field("face-x", face_corner(crop.x, region.face.centre[0]))
                    .field("face-y", face_corner(crop.y, region.face.centre[1]))
                    .field("face-size", face_size.round() as u32)
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
    pub(super) fn map_writable<'a>(
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
}
