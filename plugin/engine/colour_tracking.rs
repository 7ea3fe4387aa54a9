//! Beyond the paper: the colour of a predicted source light, taken from how the
//! face's own colour changes.
//!
//! The light decoder reads the screen's brightness from the face but hardly its
//! colour, least of all for someone it was not trained on: a face's colour is as
//! much its skin's as its light's, and one frame cannot tell them apart. Over
//! time the skin stays the same, so in log chromaticity the face's departure from
//! its own slow mean is the light's departure, whoever the person is. The tracker
//! keeps the slow mean of the prediction's colour (where the decoder's guess at
//! the absolute colour is all there is) and replaces the prediction's departure
//! from it by the face's, times a gain: the face takes a share of its light from
//! the room, so its colour moves less than the screen's.
//!
//! [`CHROMA_GAIN`] was fitted, and [`SLOW_MEAN_WEIGHT`] chosen, on the simulator's
//! 32 training people at the desk, with the face region [`face_colour`] reads, and
//! both scored on 8 people the starter never saw
//! (`python -m lsyd.evaluation.colour_tracking`; docs/accuracy.md, "The predicted
//! light's colour, tracked from the face").

use std::ops::Range;

use crate::frame::FacePlace;
use crate::light::{LIGHT_COLS, LIGHT_ROWS, Light, srgb_to_linear};

/// Weight of each frame the network runs on in the slow means: a time constant of
/// 200 such frames. It counts network runs, not time: 20 s of a 30 fps stream when
/// the network runs on every third frame (`reuse-interval` 3, a still scene), 7 s
/// when it runs on every frame. [`CHROMA_GAIN`] was fitted at this weight.
pub const SLOW_MEAN_WEIGHT: f32 = 0.005;

/// How far the light's log chromaticity moves per unit of the face's, for
/// ln(red/green) and ln(blue/green): least squares over the training people at
/// [`SLOW_MEAN_WEIGHT`] (results/colour_tracking/table.md).
pub const CHROMA_GAIN: [f32; 2] = [1.92, 1.96];

/// The face's part of the crop, in face heights from the face's centre: the
/// cheeks, nose, eyes and mouth, without hair or background.
const HALF_WIDTH: f32 = 0.3;
const HALF_HEIGHT: f32 = 0.35;

/// Channel values below this are read as this, so that a black channel has a
/// finite logarithm.
const FLOOR: f32 = 1e-4;

/// The rows and columns of a `res` × `res` network input that hold the face's
/// centre, where `face` says the face is.
fn face_region(res: usize, face: FacePlace) -> (Range<usize>, Range<usize>) {
    let span = |centre: f32, half: f32| {
        let lo = ((centre - half * face.height) * res as f32)
            .floor()
            .max(0.0) as usize;
        let hi = ((centre + half * face.height) * res as f32).ceil() as usize;
        let lo = lo.min(res - 1);
        lo..hi.clamp(lo + 1, res)
    };
    (
        span(face.centre[1], HALF_HEIGHT),
        span(face.centre[0], HALF_WIDTH),
    )
}

/// The mean linear colour of the face's centre in a network input (planar sRGB
/// in [0, 1], 3 × `res` × `res`), where `face` says the face is.
pub fn face_colour(image: &[f32], res: usize, face: FacePlace) -> [f32; 3] {
    let (rows, cols) = face_region(res, face);
    let plane = res * res;
    let n = (rows.len() * cols.len()) as f32;
    std::array::from_fn(|c| {
        let sum: f32 = rows
            .clone()
            .map(|y| {
                let row = &image[c * plane + y * res..][cols.clone()];
                row.iter().map(|&v| srgb_to_linear(v)).sum::<f32>()
            })
            .sum();
        sum / n
    })
}

/// ln(red/green) and ln(blue/green) of a colour.
fn chroma(rgb: [f32; 3]) -> [f32; 2] {
    let [r, g, b] = rgb.map(|v| v.max(FLOOR));
    [(r / g).ln(), (b / g).ln()]
}

fn mean_colour(light: &Light) -> [f32; 3] {
    let n = LIGHT_ROWS * LIGHT_COLS;
    std::array::from_fn(|c| light.0[c * n..(c + 1) * n].iter().sum::<f32>() / n as f32)
}

/// The slow means of the face's and the prediction's log chromaticity.
#[derive(Clone, Copy, Debug)]
struct Means {
    face: [f32; 2],
    light: [f32; 2],
}

/// Follows the face's colour changes in the predicted source light.
#[derive(Clone, Debug)]
pub struct ColourTracker {
    weight: f32,
    means: Option<Means>,
}

impl ColourTracker {
    pub fn new(weight: f32) -> Self {
        Self {
            weight: weight.clamp(0.0, 1.0),
            means: None,
        }
    }

    /// Adds this frame's face colour ([`face_colour`]) and predicted light, and
    /// returns the light recoloured: its slow mean colour moved as far as the face's
    /// colour departs from its own, times [`CHROMA_GAIN`], at the same sum of its
    /// three channels. The first frame after a reset passes unchanged. A light that
    /// is not finite passes unchanged and leaves the means as they were.
    pub fn push(&mut self, face: [f32; 3], light: Light) -> Light {
        if !light.is_finite() || face.iter().any(|v| !v.is_finite()) {
            return light;
        }
        let rgb = mean_colour(&light);
        let (face_now, light_now) = (chroma(face), chroma(rgb));
        let Some(means) = self.means.as_mut() else {
            self.means = Some(Means {
                face: face_now,
                light: light_now,
            });
            return light;
        };
        for k in 0..2 {
            means.face[k] += self.weight * (face_now[k] - means.face[k]);
            means.light[k] += self.weight * (light_now[k] - means.light[k]);
        }
        let wanted: [f32; 2] = std::array::from_fn(|k| {
            means.light[k] + CHROMA_GAIN[k] * (face_now[k] - means.face[k])
        });
        let gains = [
            (wanted[0] - light_now[0]).exp(),
            1.0,
            (wanted[1] - light_now[1]).exp(),
        ];
        let total: f32 = rgb.iter().sum();
        let tinted: f32 = rgb.iter().zip(gains).map(|(v, g)| v * g).sum();
        let keep = if tinted > 0.0 { total / tinted } else { 1.0 };
        let n = LIGHT_ROWS * LIGHT_COLS;
        let mut out = light.0;
        for (c, g) in gains.iter().enumerate() {
            for v in &mut out[c * n..(c + 1) * n] {
                *v = (*v * g * keep).clamp(0.0, 1.0);
            }
        }
        Light(out)
    }

    pub fn reset(&mut self) {
        self.means = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat network input of one sRGB colour.
    fn image(res: usize, rgb: [f32; 3]) -> Vec<f32> {
        rgb.iter()
            .flat_map(|&v| std::iter::repeat_n(v, res * res))
            .collect()
    }

    fn face() -> FacePlace {
        FacePlace::by_rule(2.9, 0.22)
    }

    #[test]
    fn the_face_colour_is_read_from_the_face_not_the_background() {
        let res = 96;
        let place = face();
        let grey = srgb_to_linear(0.5);
        // A grey square reaching half a face height each way from the face's centre,
        // on a white or a black background: the background must not count.
        for background in [1.0, 0.0] {
            let mut img = image(res, [background; 3]);
            let (cx, cy) = (place.centre[0] * res as f32, place.centre[1] * res as f32);
            let half = (0.5 * place.height * res as f32) as usize;
            for c in 0..3 {
                for y in cy as usize - half..cy as usize + half {
                    for x in cx as usize - half..cx as usize + half {
                        img[c * res * res + y * res + x] = 0.5;
                    }
                }
            }
            let read = face_colour(&img, res, place);
            assert!(read.iter().all(|v| (v - grey).abs() < 1e-5), "{read:?}");
        }
    }

    #[test]
    fn the_region_is_the_one_the_training_side_scores() {
        // lsyd.evaluation.colour_tracking reads the same rows and columns
        // (train/tests/test_evaluation.py).
        assert_eq!(face_region(96, face()), (43..67, 38..58));
    }

    #[test]
    fn a_face_turning_blue_turns_the_light_blue_whatever_the_skin() {
        for skin in [[0.6, 0.4, 0.3], [0.25, 0.15, 0.1]] {
            let mut tracker = ColourTracker::new(SLOW_MEAN_WEIGHT);
            let grey = Light::uniform([0.3, 0.3, 0.3]);
            tracker.push(skin, grey.clone());
            // The face gains blue and loses red; the decoder still says grey.
            let bluer = [skin[0] * 0.9, skin[1], skin[2] * 1.2];
            let out = tracker.push(bluer, grey.clone());
            let [r, g, b] = mean_colour(&out);
            assert!(b > g && g > r, "{:?}", [r, g, b]);
            // By the gain: ln(b/g) moved by CHROMA_GAIN[1] ln(1.2), less the slow mean's step.
            let moved = (b / g).ln();
            let expected = CHROMA_GAIN[1] * (1.0 - SLOW_MEAN_WEIGHT) * 1.2f32.ln();
            assert!((moved - expected).abs() < 1e-3, "{moved} vs {expected}");
            // The sum of the channels is kept.
            assert!(((r + g + b) - 0.9).abs() < 1e-4);
        }
    }

    #[test]
    fn a_steady_face_keeps_the_decoders_colour_as_its_slow_mean() {
        let mut tracker = ColourTracker::new(0.5);
        let skin = [0.5, 0.35, 0.3];
        // Equally far from grey either way in log chromaticity.
        let warm = Light::uniform([0.45, 0.3, 0.2]);
        let cool = Light::uniform([0.2, 0.3, 0.45]);
        assert_eq!(tracker.push(skin, warm.clone()), warm);
        // The face did not change: the light is the decoder's slow mean, halfway.
        let out = mean_colour(&tracker.push(skin, cool));
        assert!((out[0] / out[1] - 1.0).abs() < 1e-3, "{out:?}");
        assert!((out[2] / out[1] - 1.0).abs() < 1e-3, "{out:?}");
    }

    #[test]
    fn resets_and_broken_lights_leave_no_trace() {
        let mut tracker = ColourTracker::new(SLOW_MEAN_WEIGHT);
        let grey = Light::uniform([0.3, 0.3, 0.3]);
        tracker.push([0.5, 0.4, 0.3], grey.clone());
        let broken = Light::uniform([f32::NAN, 0.3, 0.3]);
        assert!(!tracker.push([0.5, 0.4, 0.6], broken).is_finite());
        assert_eq!(tracker.push([0.5, 0.4, 0.3], grey.clone()), grey);
        tracker.reset();
        // After a reset the first frame passes as it is, however the face changed.
        assert_eq!(tracker.push([0.2, 0.4, 0.9], grey.clone()), grey);
    }
}
