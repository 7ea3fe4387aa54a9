//! The paper's two temporal filters (section 3.3).
//!
//! - Source-light averaging: `L_avg^t = Σ_{i<N} β^i L^{t−i} / Σ_{i<N} β^i`,
//!   over the source lights of the last N face frames (β = 0.6, N = 3).
//! - Feature smoothing: `f_t = α·f_t + (1−α)·f_{t−1}` on the de-lit features
//!   f1..f7 (α = 0.7); α = 1 turns it off.
//!
//! Beyond the paper, a light predicted from the face (no monitor stream) is first
//! smoothed exponentially, `P_t = w·p_t + (1−w)·P_{t−1}`: predictions wander from
//! frame to frame with the face's own shading, and relit brightness would pump.
//! Before that its colour follows the face's colour changes
//! ([`crate::engine::colour_tracking`]).

use std::collections::VecDeque;

use crate::light::Light;

pub const DEFAULT_BETA: f32 = 0.6;
pub const DEFAULT_AVERAGE_FRAMES: usize = 3;
pub const DEFAULT_ALPHA: f32 = 0.7;
pub const DEFAULT_PREDICTION_WEIGHT: f32 = 0.2;

/// Parameters of the two filters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Temporal {
    /// Feature smoothing α; 1 turns smoothing off.
    pub alpha: f32,
    /// Source-light averaging β and frame count N; N = 1 turns averaging off.
    pub beta: f32,
    pub average_frames: usize,
    /// Weight w of a new predicted light in its exponential smoothing; 1 turns it off.
    pub prediction_weight: f32,
    /// Whether a predicted light's colour follows the face's colour changes
    /// ([`crate::engine::colour_tracking`]).
    pub colour_tracking: bool,
}

impl Default for Temporal {
    fn default() -> Self {
        Temporal {
            alpha: DEFAULT_ALPHA,
            beta: DEFAULT_BETA,
            average_frames: DEFAULT_AVERAGE_FRAMES,
            prediction_weight: DEFAULT_PREDICTION_WEIGHT,
            colour_tracking: true,
        }
    }
}

/// Weighted mean of the last N source lights, the newest weighted most.
#[derive(Clone, Debug)]
pub struct SourceLightAverager {
    beta: f32,
    frames: usize,
    /// Newest first.
    history: VecDeque<Light>,
}

impl SourceLightAverager {
    pub fn new(beta: f32, frames: usize) -> Self {
        Self {
            beta,
            frames: frames.max(1),
            history: VecDeque::new(),
        }
    }

    /// Adds this frame's source light and returns the average to use for it.
    pub fn push(&mut self, light: Light) -> Light {
        self.history.push_front(light);
        self.history.truncate(self.frames);
        let mut out = vec![0f32; self.history[0].0.len()];
        let mut norm = 0.0;
        let mut w = 1.0;
        for l in &self.history {
            for (o, v) in out.iter_mut().zip(&l.0) {
                *o += w * v;
            }
            norm += w;
            w *= self.beta;
        }
        out.iter_mut().for_each(|v| *v /= norm);
        Light(out)
    }

    pub fn reset(&mut self) {
        self.history.clear();
    }

    pub fn len(&self) -> usize {
        self.history.len()
    }

    pub fn is_empty(&self) -> bool {
        self.history.is_empty()
    }
}

/// Exponential smoothing of predicted source lights across frames.
#[derive(Clone, Debug)]
pub struct PredictionSmoother {
    weight: f32,
    state: Option<Light>,
}

impl PredictionSmoother {
    pub fn new(weight: f32) -> Self {
        Self {
            weight: weight.clamp(0.0, 1.0),
            state: None,
        }
    }

    /// Adds this frame's prediction and returns the smoothed one; the first after a
    /// reset passes unchanged.
    pub fn push(&mut self, light: Light) -> Light {
        let smoothed = match self.state.take() {
            Some(mut s) => {
                for (p, n) in s.0.iter_mut().zip(&light.0) {
                    *p += self.weight * (n - *p);
                }
                s
            }
            None => light,
        };
        self.state = Some(smoothed.clone());
        smoothed
    }

    pub fn reset(&mut self) {
        self.state = None;
    }
}

/// Exponential smoothing of the de-lit features across frames.
#[derive(Clone, Debug)]
pub struct FeatureSmoother {
    alpha: f32,
    previous: Option<Vec<Vec<f32>>>,
    /// The last processed frame's features before smoothing, for frames that are skipped.
    last_raw: Option<Vec<Vec<f32>>>,
}

impl FeatureSmoother {
    pub fn new(alpha: f32) -> Self {
        Self {
            alpha: alpha.clamp(0.0, 1.0),
            previous: None,
            last_raw: None,
        }
    }

    /// Smooths this frame's features in place and remembers them for the next frame.
    /// The first frame after a reset passes unchanged.
    pub fn smooth(&mut self, features: &mut [&mut [f32]]) {
        keep_copy(&mut self.last_raw, features);
        if let Some(prev) = &self.previous
            && prev.len() == features.len()
            && prev
                .iter()
                .zip(features.iter())
                .all(|(p, f)| p.len() == f.len())
        {
            let (a, b) = (self.alpha, 1.0 - self.alpha);
            for (f, p) in features.iter_mut().zip(prev) {
                for (x, y) in f.iter_mut().zip(p) {
                    *x = a * *x + b * y;
                }
            }
        }
        keep_copy(&mut self.previous, features);
    }

    /// Advances the state for a skipped frame, as if the last processed frame's
    /// features had been seen again: what a static scene would have given.
    pub fn repeat_last(&mut self) {
        if let (Some(prev), Some(raw)) = (&mut self.previous, &self.last_raw) {
            let (a, b) = (self.alpha, 1.0 - self.alpha);
            for (p, r) in prev.iter_mut().zip(raw) {
                for (x, y) in p.iter_mut().zip(r) {
                    *x = a * y + b * *x;
                }
            }
        }
    }

    pub fn reset(&mut self) {
        self.previous = None;
        self.last_raw = None;
    }

    pub fn has_state(&self) -> bool {
        self.previous.is_some()
    }

    /// The last frame's smoothed features, which the next frame is smoothed with.
    pub fn state(&self) -> Option<&[Vec<f32>]> {
        self.previous.as_deref()
    }
}

/// Copies `features` into `slot`, reusing its allocations.
fn keep_copy(slot: &mut Option<Vec<Vec<f32>>>, features: &[&mut [f32]]) {
    match slot {
        Some(v) if v.len() == features.len() => {
            for (p, f) in v.iter_mut().zip(features) {
                p.clear();
                p.extend_from_slice(f);
            }
        }
        _ => *slot = Some(features.iter().map(|f| f.to_vec()).collect()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn light(v: f32) -> Light {
        Light::uniform([v, v, v])
    }

    #[test]
    fn averaging_follows_the_papers_weights() {
        let mut a = SourceLightAverager::new(0.6, 3);
        assert_eq!(a.push(light(1.0)).0[0], 1.0);
        // Two frames: (1·0.5 + 0.6·1.0) / 1.6
        let two = a.push(light(0.5)).0[0];
        assert!((two - (0.5 + 0.6) / 1.6).abs() < 1e-6);
        // Three frames, newest first 0.0, 0.5, 1.0.
        let three = a.push(light(0.0)).0[0];
        assert!((three - (0.0 + 0.6 * 0.5 + 0.36 * 1.0) / 1.96).abs() < 1e-6);
        // The oldest falls out after N.
        let four = a.push(light(0.0)).0[0];
        assert!((four - (0.0 + 0.0 + 0.36 * 0.5) / 1.96).abs() < 1e-6);
    }

    #[test]
    fn smoothing_is_exponential_and_resets() {
        let mut s = FeatureSmoother::new(0.7);
        let mut f = vec![1.0f32; 4];
        s.smooth(&mut [&mut f]);
        assert_eq!(f, vec![1.0; 4]);
        let mut g = vec![0.0f32; 4];
        s.smooth(&mut [&mut g]);
        assert!(g.iter().all(|v| (v - 0.3).abs() < 1e-6));
        let mut h = vec![0.0f32; 4];
        s.smooth(&mut [&mut h]);
        assert!(h.iter().all(|v| (v - 0.09).abs() < 1e-6));
        s.reset();
        let mut k = vec![5.0f32; 4];
        s.smooth(&mut [&mut k]);
        assert_eq!(k, vec![5.0; 4]);
    }

    #[test]
    fn skipped_frames_repeat_the_last_features() {
        let mut skipping = FeatureSmoother::new(0.7);
        let mut every = FeatureSmoother::new(0.7);
        let mut a = vec![1.0f32; 3];
        let mut b = vec![0.0f32; 3];
        skipping.smooth(&mut [&mut a.clone()]);
        every.smooth(&mut [&mut a]);
        skipping.smooth(&mut [&mut b.clone()]);
        every.smooth(&mut [&mut b]);
        // Two more frames equal to the last: processed by one, skipped by the other.
        for _ in 0..2 {
            every.smooth(&mut [&mut [0.0f32; 3]]);
            skipping.repeat_last();
        }
        assert_eq!(skipping.state(), every.state());
    }

    #[test]
    fn predictions_are_smoothed_exponentially_and_reset() {
        let mut p = PredictionSmoother::new(0.25);
        assert_eq!(p.push(light(1.0)).0[0], 1.0);
        assert!((p.push(light(0.0)).0[0] - 0.75).abs() < 1e-6);
        assert!((p.push(light(0.0)).0[0] - 0.5625).abs() < 1e-6);
        p.reset();
        assert_eq!(p.push(light(0.2)).0[0], 0.2);
        let mut off = PredictionSmoother::new(1.0);
        off.push(light(1.0));
        assert_eq!(off.push(light(0.3)).0[0], 0.3);
    }

    #[test]
    fn alpha_one_turns_smoothing_off() {
        let mut s = FeatureSmoother::new(1.0);
        let mut f = vec![1.0f32; 2];
        s.smooth(&mut [&mut f]);
        let mut g = vec![3.0f32; 2];
        s.smooth(&mut [&mut g]);
        assert_eq!(g, vec![3.0; 2]);
    }
}
