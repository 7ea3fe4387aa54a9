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
//! keeping its own brightness (that mean): its light's side and strength.
//!
//! The colour difference is smooth and changes slowly (the paste blurs colour
//! over most of the crop), so the second decode runs every
//! [`REFRESH_INTERVAL`] network frames and the difference is carried between,
//! also over the small steps of a target's fade, a video target's or a
//! screen's frames ([`LIGHT_JUMP`]) and a face's motion ([`FACE_JUMP`]).

use crate::frame::{Crop, GAIN_EPSILON};
use crate::light::Light;

/// Network frames a colour difference is carried over before the decoder runs
/// again with the target spread evenly: a fourth of the second decode's cost.
/// (The property's blurb and README.md say "every 4th network frame".)
pub const REFRESH_INTERVAL: u32 = 4;

/// Mean absolute change of the target light, or of the source light the face
/// is de-lit with (linear, [`Light::distance`]), beyond which the carried
/// difference belongs to another light and the spread is decoded at once: a
/// new preset (`warm-key-left` to `cool-key-right` is about 0.5 apart), a cut
/// in a video target or on the screen. The steps of a fade and a video's
/// frames move it less and keep the difference, refreshed every
/// [`REFRESH_INTERVAL`], so they cost no more than a still light.
pub const LIGHT_JUMP: f32 = 0.05;

/// How far the face's crop may move (its centre, or its side changing) between
/// network frames, as a share of its side, before the carried difference is
/// taken for another face's: the difference lies pixel by pixel on the crop.
pub const FACE_JUMP: f32 = 0.25;

/// Mean absolute departure (linear) of a light from its spread under which it
/// counts as even already, so the second decode would change nothing: as the
/// policy's default tolerance for a source light equal to the target.
const EVEN_TOLERANCE: f32 = 0.004;

/// The target spread evenly and the colour difference it makes, for one
/// stream.
#[derive(Clone, Debug, Default)]
pub struct SpreadColour {
    /// The target light spread evenly; `None` when the target is already even
    /// (its own colour is the one wanted) or none is set.
    light: Option<Light>,
    /// Its code, computed when first decoded with.
    code: Option<Vec<f32>>,
    /// Per channel (planar, 3 × R × R), the spread image's colour less the
    /// target's own, in log gain, from the last second decode.
    difference: Option<Vec<f32>>,
    /// Network frames since `difference` was computed.
    age: u32,
    /// The face's crop on the last network frame.
    crop: Option<Crop>,
    /// The source light the face was de-lit with on the last network frame.
    source: Option<Light>,
}

impl SpreadColour {
    /// `light` spread evenly over the grid: each channel its mean. `None` when
    /// `light` is within [`EVEN_TOLERANCE`] of it already.
    pub fn spread(light: &Light) -> Option<Light> {
        let cells = light.0.len() / 3;
        let mean =
            |c: usize| light.0[c * cells..(c + 1) * cells].iter().sum::<f32>() / cells as f32;
        let spread = Light::uniform([mean(0), mean(1), mean(2)]);
        (light.distance(&spread) > EVEN_TOLERANCE).then_some(spread)
    }

    /// A new target light. The last difference is kept when the target moved by
    /// no more than [`LIGHT_JUMP`] (`jumped` false) and stays uneven, and
    /// dropped otherwise.
    pub fn retarget(&mut self, target: &Light, jumped: bool) {
        let light = Self::spread(target);
        if jumped || light.is_none() {
            self.forget();
        }
        if light != self.light {
            self.code = None;
        }
        self.light = light;
    }

    /// Follows the face to `crop` on a network frame: a jump of more than
    /// [`FACE_JUMP`] from the last one drops the difference.
    pub fn follow_face(&mut self, crop: Crop) {
        if self.crop.is_some_and(|last| jumped(last, crop)) {
            self.forget();
        }
        self.crop = Some(crop);
    }

    /// Follows the source light the face is de-lit with on a network frame: a
    /// change of more than [`LIGHT_JUMP`] from the last one drops the
    /// difference, which was read off differently de-lit features.
    pub fn follow_source(&mut self, source: &Light) {
        if self
            .source
            .as_ref()
            .is_some_and(|last| last.distance(source) > LIGHT_JUMP)
        {
            self.forget();
        }
        // Called every network frame: the last light's buffer is reused.
        match &mut self.source {
            Some(last) => last.0.clone_from(&source.0),
            None => self.source = Some(source.clone()),
        }
    }

    /// Forgets the last difference (the stream's state starts afresh); the
    /// target stays.
    pub fn forget(&mut self) {
        self.difference = None;
        self.age = 0;
    }

    /// Whether this network frame is to decode the spread: the target is
    /// uneven, and there is no difference yet or it is [`REFRESH_INTERVAL`]
    /// frames old.
    pub fn due(&self) -> bool {
        self.light.is_some() && (self.difference.is_none() || self.age >= REFRESH_INTERVAL)
    }

    /// The spread light's code, by `encode` the first time it is asked for;
    /// `None` for an even target.
    pub fn code<E>(
        &mut self,
        encode: impl FnOnce(&Light) -> Result<Vec<f32>, E>,
    ) -> Result<Option<&[f32]>, E> {
        let Some(light) = &self.light else {
            return Ok(None);
        };
        if self.code.is_none() {
            self.code = Some(encode(light)?);
        }
        Ok(self.code.as_deref())
    }

    /// Takes the colour difference between `spread` (decoded with the spread
    /// code) and `relit` (with the target's own), both planar sRGB of the same
    /// size. A difference that is not finite (the network's NaN) is not kept.
    pub fn learn(&mut self, relit: &[f32], spread: &[f32]) {
        debug_assert_eq!(relit.len(), spread.len());
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
    /// (`(v' + ε) = (v + ε) · e^d`, so the mean of each pixel's channels' logs
    /// stays) and kept in [0, 1]; as it is with none. Counts a network frame.
    pub fn apply(&mut self, mut relit: Vec<f32>) -> Vec<f32> {
        self.age = self.age.saturating_add(1);
        if let Some(difference) = &self.difference {
            debug_assert_eq!(relit.len(), difference.len());
            for (v, d) in relit.iter_mut().zip(difference) {
                *v = ((*v + GAIN_EPSILON) * d.exp() - GAIN_EPSILON).clamp(0.0, 1.0);
            }
        }
        relit
    }
}

/// Whether the crop moved from `last` to `now` by more than [`FACE_JUMP`] of
/// its side.
fn jumped(last: Crop, now: Crop) -> bool {
    let side = last.size.max(1) as f32;
    let centre = |c: Crop| [c.x, c.y].map(|v| v as f32 + c.size as f32 / 2.0);
    let ([x0, y0], [x1, y1]) = (centre(last), centre(now));
    (x1 - x0).hypot(y1 - y0) > FACE_JUMP * side || (now.size as f32 - side).abs() > FACE_JUMP * side
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::{LIGHT_COLS, LIGHT_ROWS};

    /// A face's crop in the frame, where the tests' frames begin.
    const FACE: Crop = Crop {
        x: 100,
        y: 100,
        size: 200,
    };

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
        colour.retarget(&key_left(), true);
        assert!(colour.due(), "the first frame decodes the spread");
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
    fn the_result_stays_in_range() {
        let mut colour = SpreadColour::default();
        colour.retarget(&key_left(), true);
        colour.learn(&[0.9, 0.9, 0.01], &[0.01, 0.9, 0.9]);
        assert!(
            colour
                .apply(vec![1.0, 1.0, 0.0])
                .iter()
                .all(|v| (0.0..=1.0).contains(v))
        );
    }

    /// Network frames of `colour` with the face at `crop`, each after the
    /// target moved (a step of a fade or a video's next frame, or a new target
    /// when `jumped`) when `Some`; returns how many decoded the spread.
    fn decodes(colour: &mut SpreadColour, frames: u32, jump: Option<bool>, crop: Crop) -> u32 {
        let image = vec![0.5; 3 * 4];
        let mut decodes = 0;
        for _ in 0..frames {
            if let Some(jumped) = jump {
                colour.retarget(&key_left(), jumped);
            }
            colour.follow_face(crop);
            if colour.due() {
                decodes += 1;
                colour.learn(&image, &image);
            }
            colour.apply(image.clone());
        }
        decodes
    }

    #[test]
    fn the_difference_is_refreshed_every_interval_and_kept_over_small_steps() {
        let face = FACE;
        let mut colour = SpreadColour::default();
        assert!(!colour.due(), "no target, nothing to decode");
        colour.retarget(&key_left(), true);
        assert_eq!(decodes(&mut colour, 3 * REFRESH_INTERVAL, None, face), 3);
        assert_eq!(
            decodes(&mut colour, 3 * REFRESH_INTERVAL, Some(false), face),
            3,
            "a fading or video target costs no more than a still one"
        );
        assert_eq!(decodes(&mut colour, 1, None, face), 1, "due again");
        let moved = Crop { x: 110, ..face };
        assert_eq!(
            decodes(&mut colour, REFRESH_INTERVAL - 1, None, moved),
            0,
            "a face moving a little keeps the difference"
        );
    }

    #[test]
    fn a_new_target_an_even_one_a_face_jump_or_a_screen_cut_drops_the_difference() {
        let face = FACE;
        let mut colour = SpreadColour::default();
        colour.retarget(&key_left(), true);
        decodes(&mut colour, 1, None, face);
        assert_eq!(
            decodes(&mut colour, 3, Some(true), face),
            3,
            "each jump of the target decodes at once"
        );
        let elsewhere = Crop { x: 300, ..face };
        assert_eq!(
            decodes(&mut colour, 1, None, elsewhere),
            1,
            "another face decodes at once"
        );
        assert_eq!(decodes(&mut colour, 1, Some(true), face), 1);
        colour.follow_source(&Light::uniform([0.9, 0.1, 0.1]));
        colour.follow_source(&Light::uniform([0.88, 0.1, 0.1]));
        assert!(
            !colour.due(),
            "a screen changing a little keeps the difference"
        );
        colour.follow_source(&Light::uniform([0.1, 0.1, 0.9]));
        assert!(colour.due(), "a cut on the screen decodes at once");
        colour.retarget(&Light::uniform([0.5; 3]), false);
        assert!(!colour.due(), "an even target needs no second decode");
        colour.retarget(&key_left(), false);
        assert!(colour.due(), "no difference is kept across an even target");
    }

    #[test]
    fn the_spread_code_is_encoded_once_a_target_and_only_when_asked() {
        let mut colour = SpreadColour::default();
        let encodes = std::cell::Cell::new(0);
        let encode = |_: &Light| -> Result<Vec<f32>, ()> {
            encodes.set(encodes.get() + 1);
            Ok(vec![0.0; 4])
        };
        colour.retarget(&key_left(), true);
        assert!(colour.code(encode).unwrap().is_some());
        assert!(colour.code(encode).unwrap().is_some());
        colour.retarget(&key_left(), false);
        assert!(colour.code(encode).unwrap().is_some());
        assert_eq!(encodes.get(), 1, "the same spread is encoded once");
        colour.retarget(&Light::uniform([0.5; 3]), false);
        assert!(colour.code(encode).unwrap().is_none());
        assert_eq!(encodes.get(), 1, "an even target encodes nothing");
    }

    #[test]
    fn a_broken_spread_image_is_not_kept() {
        let own = vec![0.5; 3];
        let mut colour = SpreadColour::default();
        colour.retarget(&key_left(), true);
        colour.learn(&own, &[f32::NAN, 0.5, 0.5]);
        assert!(colour.due(), "still due: nothing was learnt");
        assert_eq!(colour.apply(own.clone()), own);
    }
}
