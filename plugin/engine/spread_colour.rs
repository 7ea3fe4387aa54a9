//! The relit face's colour taken from the target light spread evenly over the
//! light code's grid (not in the paper).
//!
//! The network colours a face by a light that fills the grid about as the
//! truth does, but by a light on part of it (a key from one side, a sunset's
//! band) much less: the starter gives a face half of `warm-key-left`'s warmth
//! and 0.71 of the preset `sunset`'s, yet all of either spread evenly
//! (`lsyd.evaluation.key_colour`, docs/targets.md). A light's place changes
//! where it falls on the face far more than the face's colour, so the decoder
//! runs a second time on the same de-lit features with the target spread
//! evenly (each channel its mean over the grid), and the relit image takes that
//! image's colour (each channel's log gain less the channels' mean) while
//! keeping its own brightness: its light's side and strength.
//!
//! The colour difference is smooth and changes slowly (the paste blurs colour
//! over most of the crop), so the second decode runs every
//! [`REFRESH_INTERVAL`] network frames and the difference is carried between.

use crate::frame::GAIN_EPSILON;
use crate::light::Light;

/// Network frames a colour difference is carried over before the decoder runs
/// again with the target spread evenly: a fourth of the second decode's cost.
pub const REFRESH_INTERVAL: u32 = 4;

/// The target spread evenly and the colour difference it makes, for one
/// stream.
#[derive(Clone, Debug, Default)]
pub struct SpreadColour {
    /// The code of the target light spread evenly; `None` when the target is
    /// already even (its own colour is the one wanted) or none is set.
    code: Option<Vec<f32>>,
    /// Per channel (planar, 3 × R × R), the spread image's colour less the
    /// target's own, in log gain, from the last second decode.
    difference: Option<Vec<f32>>,
    /// Network frames since `difference` was computed.
    age: u32,
}

impl SpreadColour {
    /// `light` spread evenly over the grid: each channel its mean. `None` when
    /// every cell already has the same light (within 1e-6), so the spread
    /// changes nothing.
    pub fn spread(light: &Light) -> Option<Light> {
        let cells = light.0.len() / 3;
        let channels: Vec<&[f32]> = light.0.chunks_exact(cells).collect();
        let uneven = channels
            .iter()
            .any(|channel| channel.iter().any(|v| (v - channel[0]).abs() > 1e-6));
        uneven.then(|| {
            Light::uniform([0, 1, 2].map(|c| channels[c].iter().sum::<f32>() / cells as f32))
        })
    }

    /// A new target's spread code (`None` for an even target): the last
    /// difference belonged to the old one.
    pub fn retarget(&mut self, code: Option<Vec<f32>>) {
        *self = SpreadColour {
            code,
            ..SpreadColour::default()
        };
    }

    /// Forgets the last difference (the stream's state starts afresh); the
    /// target's code stays.
    pub fn reset(&mut self) {
        self.difference = None;
        self.age = 0;
    }

    /// The spread code to decode with on this network frame, when a new
    /// difference is due: none yet, or [`REFRESH_INTERVAL`] frames old.
    pub fn due(&self) -> Option<&[f32]> {
        let stale = self.difference.is_none() || self.age >= REFRESH_INTERVAL;
        self.code.as_deref().filter(|_| stale)
    }

    /// Takes the colour difference between `spread` (decoded with the spread
    /// code) and `relit` (with the target's own), both planar sRGB of the same
    /// size. A difference that is not finite is not kept.
    pub fn learn(&mut self, relit: &[f32], spread: &[f32]) {
        let n = relit.len() / 3;
        let log_ratio = |c: usize, i: usize| {
            ((spread[c * n + i] + GAIN_EPSILON) / (relit[c * n + i] + GAIN_EPSILON)).ln()
        };
        let mut difference = vec![0.0; relit.len()];
        for i in 0..n {
            let ratio = [0, 1, 2].map(|c| log_ratio(c, i));
            let mean = (ratio[0] + ratio[1] + ratio[2]) / 3.0;
            for c in 0..3 {
                difference[c * n + i] = ratio[c] - mean;
            }
        }
        if difference.iter().all(|d| d.is_finite()) {
            self.difference = Some(difference);
            self.age = 0;
        }
    }

    /// `relit` with the last colour difference applied, pixel by pixel
    /// (`(v' + ε) = (v + ε) · e^d`, so each pixel's brightness stays); as it is
    /// with none, or when its size is not the difference's. Counts a network
    /// frame.
    pub fn apply(&mut self, mut relit: Vec<f32>) -> Vec<f32> {
        self.age = self.age.saturating_add(1);
        if let Some(difference) = self.difference.as_ref().filter(|d| d.len() == relit.len()) {
            for (v, d) in relit.iter_mut().zip(difference) {
                *v = (*v + GAIN_EPSILON) * d.exp() - GAIN_EPSILON;
            }
        }
        relit
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::{LIGHT_COLS, LIGHT_ROWS};

    /// A light bright warm in its left third, dim grey elsewhere: a key from the left.
    fn key_left() -> Light {
        let cells = LIGHT_ROWS * LIGHT_COLS;
        let warm = [1.0, 0.7, 0.4];
        Light(
            (0..3)
                .flat_map(|c| {
                    (0..cells).map(move |i| {
                        if i % LIGHT_COLS < LIGHT_COLS / 3 {
                            warm[c]
                        } else {
                            0.05
                        }
                    })
                })
                .collect(),
        )
    }

    #[test]
    fn a_light_spreads_to_its_mean_and_an_even_one_not_at_all() {
        let spread = SpreadColour::spread(&key_left()).expect("a key is uneven");
        let cells = LIGHT_ROWS * LIGHT_COLS;
        let third = (LIGHT_COLS / 3) as f32 / LIGHT_COLS as f32;
        let red = third * 1.0 + (1.0 - third) * 0.05;
        assert!(spread.0[..cells].iter().all(|v| (v - red).abs() < 1e-5));
        assert!(SpreadColour::spread(&Light::uniform([0.3, 0.2, 0.1])).is_none());
    }

    /// Two pixels: the target's own image warms one and cools the other; the
    /// spread image is warm at twice the brightness. The result has the spread
    /// image's colour and the own image's brightness.
    #[test]
    fn the_colour_comes_from_the_spread_and_the_brightness_stays() {
        let own = vec![0.6, 0.2, /* G */ 0.4, 0.4, /* B */ 0.2, 0.6];
        let spread = vec![0.9, 0.9, 0.6, 0.6, 0.3, 0.3];
        let mut colour = SpreadColour::default();
        colour.retarget(Some(vec![0.0; 4]));
        assert!(colour.due().is_some(), "the first frame decodes the spread");
        colour.learn(&own, &spread);
        let out = colour.apply(own.clone());
        for i in 0..2 {
            let log = |img: &[f32], c: usize| (img[c * 2 + i] + GAIN_EPSILON).ln();
            let mean = |img: &[f32]| (log(img, 0) + log(img, 1) + log(img, 2)) / 3.0;
            assert!(
                (mean(&out) - mean(&own)).abs() < 1e-5,
                "pixel {i} keeps its brightness"
            );
            for c in 0..3 {
                let chroma = |img: &[f32]| log(img, c) - mean(img);
                assert!(
                    (chroma(&out) - chroma(&spread)).abs() < 1e-5,
                    "pixel {i} channel {c}"
                );
            }
        }
    }

    #[test]
    fn the_difference_is_refreshed_every_interval_and_forgotten_on_a_new_target() {
        let image = vec![0.5; 3 * 4];
        let mut colour = SpreadColour::default();
        assert!(colour.due().is_none(), "no target, nothing to decode");
        colour.retarget(Some(vec![0.0; 4]));
        let mut decodes = 0;
        for _ in 0..3 * REFRESH_INTERVAL {
            if colour.due().is_some() {
                decodes += 1;
                colour.learn(&image, &image);
            }
            colour.apply(image.clone());
        }
        assert_eq!(decodes, 3);
        colour.retarget(Some(vec![1.0; 4]));
        assert!(colour.due().is_some(), "a new target decodes at once");
        colour.retarget(None);
        assert!(colour.due().is_none(), "an even target never decodes twice");
    }

    #[test]
    fn a_broken_spread_image_is_not_kept() {
        let own = vec![0.5; 3];
        let mut colour = SpreadColour::default();
        colour.retarget(Some(vec![0.0; 4]));
        colour.learn(&own, &[f32::NAN, 0.5, 0.5]);
        assert!(colour.due().is_some(), "still due: nothing was learnt");
        assert_eq!(colour.apply(own.clone()), own);
    }
}
