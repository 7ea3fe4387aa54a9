//! The lighting change at network resolution, from the network's input and
//! output: per RGB channel the log of a smooth gain, `(v' + ε) = g · (v + ε)`,
//! its brightness blurred over much of the crop with the face's own shading
//! passed whole, and its colour blurred alike. [`gain_field`](super::gain_field)
//! pastes it onto the frame.

use super::gain_field::GainField;
use super::{Crop, FrameMut, luma};

/// Constant of the gain `g`: keeps dark regions from amplifying noise.
pub const GAIN_EPSILON: f32 = 0.02;
/// Largest gain applied to the frame's detail, and the most the relit image may
/// brighten the input (plus [`INVENTED_LIGHT`]).
pub(super) const MAX_GAIN: f32 = 4.0;
/// Luma (sRGB, [0, 1]) the relit image may add where the input is black. The
/// network has learnt its person's face and can draw it into darkness; light the
/// input does not carry is invented, so it is bounded to about 1 level in 8 bits.
const INVENTED_LIGHT: f32 = 0.004;

/// The lighting change at network resolution: per RGB channel the log of a
/// smooth gain of the frame, `(v' + ε) = g · (v + ε)`, taken from the network's
/// output over its input. Applied as a [`GainField`] that carries it beyond the
/// crop and fades it out round head and shoulders, so the change has no edge
/// anywhere in the frame.
pub struct LightingChange {
    pub(super) res: usize,
    /// Per channel (R, G, B), the log of the gain, smoothed, res × res.
    pub(super) log_gain: [Vec<f32>; 3],
    /// Where the face is in the crop: the field's silhouette is placed by it.
    pub(super) face: FacePlace,
}

/// Where the face is in the network's crop, in fractions of the crop's side:
/// its centre and its height (BlazeFace's box, hairline to chin). The crop
/// rule puts it at the same place in every crop, unless the crop was moved
/// to stay inside the frame (a face near the frame's top sits higher in it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FacePlace {
    pub centre: [f32; 2],
    pub height: f32,
}

impl FacePlace {
    /// Where the crop rule of `side` face heights across, its centre `lift`
    /// face heights above the face's, puts the face.
    pub fn by_rule(side: f32, lift: f32) -> FacePlace {
        FacePlace {
            centre: [0.5, 0.5 + lift / side],
            height: 1.0 / side,
        }
    }
}

impl Default for FacePlace {
    /// Where the training captures' rule puts the face.
    fn default() -> Self {
        FacePlace::by_rule(crate::face::CROP_SIDE, crate::face::CROP_LIFT)
    }
}

impl LightingChange {
    /// From the network's input and output (planar sRGB in [0, 1], 3 × res ×
    /// res), the face at `face` in the crop.
    pub fn new(input: &[f32], relit: &[f32], res: usize, face: FacePlace) -> LightingChange {
        // At the network's own resolution, not halved: the face's finest
        // shading (FACE_DETAIL_SMOOTHING) is a network pixel or two across.
        let relit = bound_invented_light(input, relit, res * res);
        LightingChange {
            res,
            log_gain: smooth_log_gain(input, &relit, res, face),
            face,
        }
    }

    /// Applies the change round `crop` of `frame`: whole near the face, fading
    /// out over `feather` pixels (see [`GainField`]).
    pub fn apply(&self, frame: &mut FrameMut, crop: Crop, feather: usize) {
        self.apply_faded(frame, crop, feather, 1.0);
    }

    /// [`LightingChange::apply`], shown at `strength` in [0, 1] (a face fading in or out).
    pub fn apply_faded(&self, frame: &mut FrameMut, crop: Crop, feather: usize, strength: f32) {
        let size = (frame.width, frame.height);
        GainField::new(
            self,
            crop,
            feather,
            strength,
            frame.format,
            frame.matrix,
            size,
        )
        .paste(frame);
    }

    /// Bilinear sample of a res × res `map` at `u` (fractions of the crop),
    /// taken at the crop's nearest point when `u` lies outside it.
    pub(super) fn sample(&self, map: &[f32], u: [f32; 2]) -> f32 {
        let res = self.res;
        let last = (res - 1) as f32;
        let [(x, tx), (y, ty)] = u.map(|u| {
            let p = (u * res as f32 - 0.5).clamp(0.0, last);
            let lo = p.floor() as usize;
            (lo, p - lo as f32)
        });
        let at = |x: usize, y: usize| map[y * res + x];
        let (x1, y1) = ((x + 1).min(res - 1), (y + 1).min(res - 1));
        let top = at(x, y) + (at(x1, y) - at(x, y)) * tx;
        let bottom = at(x, y1) + (at(x1, y1) - at(x, y1)) * tx;
        top + (bottom - top) * ty
    }
}

/// The relit image with no pixel brighter than the input allows: at most
/// `MAX_GAIN` times the input's luma plus `INVENTED_LIGHT`, scaled down in all
/// three channels so its colour stays.
fn bound_invented_light(input: &[f32], relit: &[f32], n: usize) -> Vec<f32> {
    let mut out = relit.to_vec();
    for i in 0..n {
        let (allowed, have) = (
            MAX_GAIN * luma(input, n, i) + INVENTED_LIGHT,
            luma(relit, n, i),
        );
        if have > allowed {
            let scale = allowed / have;
            for c in 0..3 {
                out[c * n + i] *= scale;
            }
        }
    }
    out
}

/// Radius, as a fraction of the network's resolution, of the blur of the
/// brightness part of the gain (its mean over the channels): a fifth of the
/// crop, so the change has no step at the edges of what the network relights
/// differently (hair and skin, a collar, a jacket against a wall).
const BRIGHTNESS_SMOOTHING: f32 = 0.45;
/// Radius of a finer blur of the brightness part: the shading the light puts
/// on the face (a nose's shadow, a lit cheek, the side a key light falls on),
/// a sixth of the face's width. A blur keeps a ramp across the face whole, so
/// the side of the light passes it.
const SHADING_SMOOTHING: f32 = 0.04;
/// How far, in log gain, the finer blur may depart from the coarse one away
/// from the face (2%): collars, shoulders and hair lines, where a finer change
/// makes steps the picture does not have.
const SHADING_DETAIL: f32 = 0.02;
/// Distances from the face's centre in the network's crop, in half face
/// heights, within which the face's shading passes whole and beyond which it
/// is held within [`SHADING_DETAIL`], blended by smoothstep between.
///
/// A blend, not a cap: the shading over the face was once clamped to 25% in
/// log gain, fading to 2% over 0.8-1.2 half face heights, and a clamp that
/// tightens with distance turns a strong change into a ring where the clamp
/// starts to bite. On the simulator's `wander` the largest step where the
/// picture has none fell from 9.7% to 5.9% (`tests/real_footage.rs`), and
/// the real faces' mottling stayed (portrait 1.77% to 1.70% over the face);
/// against exact truth every target is as before or up to 0.1 better
/// (`examples/target_lights measure --frames 30 --model models/starter`:
/// studio 12.90 to 12.80, soft-front 13.02 to 12.93, rim 5.54 to 5.51; the
/// starter then drew no side to pass).
///
/// Whole out to 1.0 half face heights (the face box's sides), not 0.6, since
/// the starter draws a light's side: the shading that tells the sides apart
/// lies at the cheeks. With the starter of 2026-12-06 the key swap rose from
/// -4.0 to -4.5 on the real portrait, -7.0 to -8.6 on the film clip and -16.0
/// to -19.0 on the simulator's call (truth -26.1; `target_lights direction`);
/// against exact truth every target moved by -0.19 to 0.00 but rim, +0.11
/// (`target_lights measure --frames 60`); the largest box edge where the
/// picture has none went 2.7% to 3.1% (portrait) and 4.5% to 8.4% (film clip,
/// I420; bar 10%), face mottling stayed (`benchmark --quality`). No window at
/// all gave -4.6 / -9.1 / -19.6 with box edges of 9.2% and 17.8% (RGB).
const FACE_SHADING_REACH: (f32, f32) = (1.0, 1.8);
/// Radius of the finest blur of the brightness part, a network pixel: the
/// face's own shading as the network drew it, which tells a light's side.
/// The shading blur ([`SHADING_SMOOTHING`], four network pixels) mixes the
/// face's two halves across its middle and takes a fifth of the side off:
/// on the real portrait the network's own warm-key-left less cool-key-right
/// was -12.0 before the blurs and -9.7 after it (face box, network crop; a
/// one-off read in `LightingChange::new`, 2026-12-08).
const FACE_DETAIL_SMOOTHING: f32 = 0.01;
/// Distances from the face's centre, in half face heights, within which the
/// finest shading passes whole (the face box's sides) and beyond which none
/// of it does (its corners), blended by smoothstep between. Farther out it
/// draws the edges of hair and of what lies behind it where the picture has
/// none: whole to 1.1 and gone by 1.5, the film clip's largest such step was
/// 9.9% (bar 10%); with this reach 8.3% (`examples/real_footage --only
/// megamind`, both on a grid of 16 cells; 8.3% on 32 too).
const FACE_DETAIL_REACH: (f32, f32) = (1.0, 1.4);

/// Per pixel of a res × res map of the network's crop, how much of the
/// face's own shading passes: 1 over the face (at `face`), within the first
/// of `reach` (in half face heights), falling by smoothstep to 0 at its second.
fn face_shading_weights(
    res: usize,
    face: FacePlace,
    reach: (f32, f32),
) -> impl Iterator<Item = f32> {
    let half_face = 0.5 * face.height;
    let (from, to) = reach;
    (0..res * res).map(move |i| {
        let u = [i % res, i / res].map(|v| (v as f32 + 0.5) / res as f32);
        let distance = (u[0] - face.centre[0]).hypot(u[1] - face.centre[1]) / half_face;
        let t = ((to - distance) / (to - from)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    })
}
/// Radius of the blur of the colour part of the gain (each channel's log gain
/// less the mean): a light's colour changes slowly over a face, and the
/// network's colour noise would otherwise blotch the skin.
const COLOUR_SMOOTHING: f32 = 0.45;

/// Two box blurs of a res × res map, of radius `fraction` of `res`, each way
/// (shrinking at the borders).
///
/// Down the columns, a whole row at a time so that the sums run over every
/// column together, then the same across the rows by way of the transpose: the
/// change takes some ten of these a network frame, at the network's
/// resolution, and a running sum along one row is a chain of dependent adds.
fn blur(field: &[f32], res: usize, fraction: f32) -> Vec<f32> {
    let radius = ((fraction * res as f32).round() as usize).max(1);
    let twice = |field: &[f32]| blur_columns(&blur_columns(field, res, radius), res, radius);
    transpose(&twice(&transpose(&twice(field), res)), res)
}

/// Per channel, the log of the gain the relit image makes of the input,
/// bounded by [`MAX_GAIN`] each way and smoothed: brightness over
/// [`BRIGHTNESS_SMOOTHING`] with the face's shading ([`SHADING_SMOOTHING`])
/// and, over the face box, its finest shading ([`FACE_DETAIL_SMOOTHING`]);
/// colour over [`COLOUR_SMOOTHING`]. A gain that is not finite (the network's NaN) counts
/// as no change.
fn smooth_log_gain(input: &[f32], relit: &[f32], res: usize, face: FacePlace) -> [Vec<f32>; 3] {
    let n = res * res;
    let log_gain = |c: usize| -> Vec<f32> {
        (c * n..(c + 1) * n)
            .map(|i| {
                let g = ((relit[i] + GAIN_EPSILON) / (input[i] + GAIN_EPSILON)).ln();
                if g.is_finite() {
                    g.clamp(-MAX_GAIN.ln(), MAX_GAIN.ln())
                } else {
                    0.0
                }
            })
            .collect()
    };
    let gains = [log_gain(0), log_gain(1), log_gain(2)];
    // Each pixel counts by its brightness: the ratios of dark pixels (hair, a
    // dark room) are the network's least certain and its largest, and would
    // otherwise spill over the face, which then clips where they do not.
    let weight: Vec<f32> = (0..n).map(|i| luma(input, n, i) + WEIGHT_FLOOR).collect();
    // Normalised convolution: the blur of weight × field over the blur of the
    // weight, the latter once per radius.
    let blurred_weight = |fraction| (fraction, blur(&weight, res, fraction));
    let [coarse_weight, shading_weight, colour_weight, finest_weight] = [
        BRIGHTNESS_SMOOTHING,
        SHADING_SMOOTHING,
        COLOUR_SMOOTHING,
        FACE_DETAIL_SMOOTHING,
    ]
    .map(blurred_weight);
    let weighted_blur = |field: &[f32], (fraction, blurred): &(f32, Vec<f32>)| -> Vec<f32> {
        let product: Vec<f32> = field.iter().zip(&weight).map(|(f, w)| f * w).collect();
        let mut out = blur(&product, res, *fraction);
        out.iter_mut().zip(blurred).for_each(|(p, w)| *p /= w);
        out
    };
    let mean: Vec<f32> = (0..n)
        .map(|i| (gains[0][i] + gains[1][i] + gains[2][i]) / 3.0)
        .collect();
    let coarse = weighted_blur(&mean, &coarse_weight);
    let finest = weighted_blur(&mean, &finest_weight);
    let brightness: Vec<f32> = coarse
        .iter()
        .zip(weighted_blur(&mean, &shading_weight))
        .zip(face_shading_weights(res, face, FACE_SHADING_REACH))
        .zip(face_shading_weights(res, face, FACE_DETAIL_REACH))
        .zip(&finest)
        .map(|((((coarse, shaded), on_face), on_face_box), finest)| {
            let shading = shaded - coarse;
            coarse
                + on_face * shading
                + (1.0 - on_face) * shading.clamp(-SHADING_DETAIL, SHADING_DETAIL)
                + on_face_box * (finest - shaded)
        })
        .collect();
    gains.map(|g| {
        let colour: Vec<f32> = g.iter().zip(&mean).map(|(g, m)| g - m).collect();
        weighted_blur(&colour, &colour_weight)
            .iter()
            .zip(&brightness)
            .map(|(c, b)| c + b)
            .collect()
    })
}

/// Added to each pixel's luma as its weight in the gain's blur, so black
/// regions still count a little.
const WEIGHT_FLOOR: f32 = 0.02;

/// A box blur of a res × res field down its columns, `radius` each way,
/// shrinking at the borders.
fn blur_columns(field: &[f32], res: usize, radius: usize) -> Vec<f32> {
    // Row y of `sums` is the sum of the field's first y rows.
    let mut sums = vec![0f32; (res + 1) * res];
    for (y, row) in field.chunks_exact(res).enumerate() {
        let (above, below) = sums.split_at_mut((y + 1) * res);
        for ((next, sum), v) in below[..res].iter_mut().zip(&above[y * res..]).zip(row) {
            *next = sum + v;
        }
    }
    let mut out = vec![0f32; field.len()];
    for (y, out) in out.chunks_exact_mut(res).enumerate() {
        let (lo, hi) = (y.saturating_sub(radius), (y + radius + 1).min(res));
        let share = 1.0 / (hi - lo) as f32;
        let (top, bottom) = (&sums[lo * res..][..res], &sums[hi * res..][..res]);
        for ((out, top), bottom) in out.iter_mut().zip(top).zip(bottom) {
            *out = (bottom - top) * share;
        }
    }
    out
}

/// A res × res field with its rows and columns swapped.
fn transpose(field: &[f32], res: usize) -> Vec<f32> {
    let mut out = vec![0f32; field.len()];
    for (y, row) in field.chunks_exact(res).enumerate() {
        for (x, v) in row.iter().enumerate() {
            out[x * res + y] = *v;
        }
    }
    out
}
