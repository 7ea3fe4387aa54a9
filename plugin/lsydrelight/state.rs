//! The face stream's state while the element runs: the per-frame policy with
//! the model's network, the followed face region, the target light's fade and
//! the denoiser, made at start; and how the element keeps it up to date before
//! each frame (resets after a break in the stream, new settings, a new target)
//! or forgets its past (flushes, seeks, caps changes, new segments).

use std::time::Instant;

use gst::prelude::*;
use gst::subclass::prelude::*;

use super::imp::{CAT, LsydRelight};
use super::region::FaceRegion;
use super::settings::Settings;
use super::video::{frame_duration, running_time};
use super::{ExecutionProvider, lock};
use crate::engine::{self, FramePolicy, Provider, Relighter};
use crate::frame::{DetailDenoiser, FrameCopy};
use crate::light::Light;
use crate::targets::Crossfade;

/// The face stream's state while the element runs.
pub(super) struct State {
    pub(super) policy: FramePolicy,
    pub(super) region: FaceRegion,
    pub(super) face_info: Option<gst_video::VideoInfo>,
    pub(super) last_face_rt: Option<gst::ClockTime>,
    /// The target generation the policy has.
    pub(super) target_generation: u64,
    /// The target light the policy is given, fading to a new one.
    pub(super) fade: Crossfade,
    /// A NaN warning was posted and no frame has been relit since.
    pub(super) nan_warned: bool,
    /// The camera's noise taken out of the face's detail (`denoise`).
    pub(super) denoiser: DetailDenoiser,
    /// The frame's bytes as they came, while it is denoised beside the network.
    pub(super) undenoised: FrameCopy,
}

impl State {
    /// Forgets the stream's past: temporal state, the followed face, the last
    /// frame's time. Returns whether there was temporal state to forget.
    pub(super) fn reset(&mut self) -> bool {
        self.region.reset();
        self.denoiser.reset();
        self.last_face_rt = None;
        self.policy.reset()
    }
}

impl LsydRelight {
    /// Forgets the face stream's temporal state: after flushes, seeks, caps changes
    /// and new segments. The monitor frame on screen stays: it is still on screen.
    pub(super) fn reset_state(&self, why: &str) {
        if let Some(state) = lock(&self.state).as_mut() {
            state.reset();
        }
        lock(&self.match_check).reset();
        gst::debug!(CAT, imp = self, "reset temporal state: {why}");
    }

    /// Brings the policy up to date for the next frame: resets after a break in the
    /// stream, new settings, a new target.
    pub(super) fn update_state(
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
        state.policy.set_spread_colour(settings.spread_colour);
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
    pub(super) fn follow_fade(&self, state: &mut State, rt: Option<gst::ClockTime>) {
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

    /// The policy with the model's network, and the face region (with the face
    /// detector when the face is followed).
    pub(super) fn start_engine(
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
