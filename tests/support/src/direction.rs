//! How strong a relighting is and which way its light falls, over a face,
//! with no ground truth: what a person sees first when a face is relit to a
//! key light from one side and then from the other.
//!
//! Both read the change in luma, `100 ln((out + 10) / (in + 10))` with luma in
//! 8-bit levels (the 10 keeps dark pixels' noise from counting as light):
//!
//! - strength: its RMS over the face, in percent;
//! - asymmetry: its mean over the face's image-left half less its mean over
//!   the image-right half, in percent. A colour grade or a change that is the
//!   same everywhere scores 0; a light from image left scores above 0.
//!
//! The key swap of two relightings of the same frames is the difference of
//! their asymmetries: how much more a key from one side brightens that side.

use crate::quality::{Pixels, Region, luma};

/// Added to luma in levels before the ratio.
const LUMA_FLOOR: f64 = 10.0;

/// The strength and asymmetry of one relit frame's change over a face.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LightShape {
    /// RMS of the change over the face, in percent.
    pub strength: f64,
    /// Mean change over the face's image-left half less its image-right half, in percent.
    pub asymmetry: f64,
    /// Mean change over the face, in percent: how much the light brightens it.
    pub mean: f64,
}

/// The shape of the change from `input` to `output` over `face` (frame pixels).
pub fn light_shape(input: &impl Pixels, output: &impl Pixels, face: Region) -> LightShape {
    let (w, h) = input.size();
    let step = input.step();
    let (x0, y0) = (face.x / step, face.y / step);
    let (x1, y1) = (
        ((face.x + face.size) / step).min(w),
        ((face.y + face.size) / step).min(h),
    );
    let middle = (x0 + x1) as f64 / 2.0;
    let (mut squares, mut count) = (0.0, 0usize);
    let (mut left, mut right) = ((0.0, 0usize), (0.0, 0usize));
    for y in y0..y1 {
        for x in x0..x1 {
            let level = |p: [f64; 3]| 255.0 * luma(p) + LUMA_FLOOR;
            let change = 100.0 * (level(output.rgb(x, y)) / level(input.rgb(x, y))).ln();
            squares += change * change;
            count += 1;
            let side = if (x as f64 + 0.5) < middle {
                &mut left
            } else {
                &mut right
            };
            side.0 += change;
            side.1 += 1;
        }
    }
    let mean = |(sum, n): (f64, usize)| sum / n.max(1) as f64;
    LightShape {
        strength: (squares / count.max(1) as f64).sqrt(),
        asymmetry: mean(left) - mean(right),
        mean: mean((left.0 + right.0, left.1 + right.1)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use deskstage::monitor::RgbImage;

    fn grey(w: usize, h: usize, level: impl Fn(usize) -> u8) -> RgbImage {
        let mut img = RgbImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                img.data[3 * (y * w + x)..][..3].fill(level(x));
            }
        }
        img
    }

    const FACE: Region = Region {
        x: 0,
        y: 0,
        size: 40,
    };

    #[test]
    fn a_light_from_image_left_is_a_positive_asymmetry() {
        let input = grey(40, 40, |_| 100);
        let output = grey(40, 40, |x| if x < 20 { 150 } else { 100 });
        let shape = light_shape(&input, &output, FACE);
        let expected = 100.0 * (160.0f64 / 110.0).ln();
        assert!((shape.asymmetry - expected).abs() < 0.5, "{shape:?}");
        assert!(shape.strength > 20.0, "{shape:?}");
    }

    #[test]
    fn an_even_change_has_strength_and_no_asymmetry() {
        let input = grey(40, 40, |_| 100);
        let output = grey(40, 40, |_| 140);
        let shape = light_shape(&input, &output, FACE);
        let expected = 100.0 * (150.0f64 / 110.0).ln();
        assert!((shape.strength - expected).abs() < 0.5, "{shape:?}");
        assert!(shape.asymmetry.abs() < 1e-9, "{shape:?}");
        assert_eq!(light_shape(&input, &input, FACE), LightShape::default());
    }
}
