use super::*;
use crate::frame::change::MAX_GAIN;
use crate::frame::gain_field::yuv::{
    YuvChange, chroma_change, chroma_change_portable, spread, spread_portable, write_lane,
};
use crate::frame::gain_field::{INNER_RADIUS, Silhouette};
use crate::frame::gain_field::{dither, gain_row, gain_row_portable};
use crate::frame::reference;

fn rgb_frame(w: usize, h: usize, f: impl Fn(usize, usize) -> [u8; 3]) -> Vec<u8> {
    let mut v = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            v[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&f(x, y));
        }
    }
    v
}

#[test]
fn yuv_matrix_round_trips() {
    for m in [YuvMatrix::BT601_LIMITED, YuvMatrix::BT709_LIMITED] {
        for rgb in [
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.8, 0.3, 0.1],
            [0.1, 0.9, 0.4],
        ] {
            let yuv = m.from_rgb(rgb);
            let back = m.to_rgb(yuv[0], yuv[1], yuv[2]);
            for c in 0..3 {
                assert!((back[c] - rgb[c]).abs() < 1e-5);
            }
        }
    }
}

#[test]
fn crop_is_centred_even_and_inside() {
    let c = Crop::centred(1280, 720, 0.5, 0.5, 1.0);
    assert_eq!(
        c,
        Crop {
            x: 280,
            y: 0,
            size: 720
        }
    );
    let c = Crop::centred(640, 480, 0.95, 0.5, 0.5);
    assert!(c.x + c.size <= 640 && c.x.is_multiple_of(2) && c.size.is_multiple_of(2));
}

#[test]
fn area_resample_of_a_uniform_crop_is_uniform() {
    let data = rgb_frame(100, 80, |_, _| [200, 100, 50]);
    let out = sample_crop(
        &Frame::packed_rgb(&data, 100, 80),
        Crop {
            x: 10,
            y: 4,
            size: 70,
        },
        32,
    );
    let n = 32 * 32;
    assert!(out[..n].iter().all(|v| (v - 200.0 / 255.0).abs() < 1e-5));
    assert!(out[2 * n..].iter().all(|v| (v - 50.0 / 255.0).abs() < 1e-5));
}

#[test]
fn a_crop_resampled_smaller_is_the_smaller_crop() {
    let mut noise = Noise(0x5eed);
    let buffers = random_frame(PixelFormat::Rgb, 200, 150, &mut noise);
    let crop = Crop {
        x: 30,
        y: 11,
        size: 128,
    };
    let full = sample_crop(&buffers.frame(), crop, 128);
    assert_eq!(resample_square(&full, 128, 128), full);
    // Whole pixels of the crop a resampled pixel: the same sums as the frame's.
    let direct = sample_crop(&buffers.frame(), crop, 64);
    let resampled = resample_square(&full, 128, 64);
    let worst = (direct.iter().zip(&resampled)).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(worst < 1e-5, "largest difference {worst:e}");
    // Between sizes that are not multiples, each plane keeps its mean.
    let from_96 = sample_crop(&buffers.frame(), crop, 96);
    let to_64 = resample_square(&from_96, 96, 64);
    for c in 0..3 {
        let mean = |img: &[f32], n: usize| img[c * n..(c + 1) * n].iter().sum::<f32>() / n as f32;
        assert!((mean(&from_96, 96 * 96) - mean(&to_64, 64 * 64)).abs() < 1e-4);
    }
}

#[test]
fn the_face_shading_passes_where_the_face_is() {
    // A key light from the image's left: the network's output 30% brighter
    // than its grey input over the left half of the crop and 30% darker over
    // the right. Away from the face the finer shading is held within 2% of a
    // blur over half the crop; over the face it passes whole. A crop moved
    // down to stay inside the frame holds the face high: the side must pass
    // there, not at the place the crop rule would have put it.
    let res = 96;
    let n = res * res;
    let input = vec![0.5f32; 3 * n];
    let relit: Vec<f32> = (0..3 * n)
        .map(|i| if i % res < res / 2 { 0.65 } else { 0.385 })
        .collect();
    let high = FacePlace {
        centre: [0.5, 0.3],
        height: 1.0 / 2.9,
    };
    // The log gain a quarter face height left of the face's centre less as
    // far right of it, over the three channels.
    let side = |change: &LightingChange, face: FacePlace| -> f32 {
        let at = |dx: f32| -> f32 {
            let u = [face.centre[0] + dx * face.height, face.centre[1]];
            (0..3)
                .map(|c| change.sample(&change.log_gain[c], u))
                .sum::<f32>()
                / 3.0
        };
        at(-0.25) - at(0.25)
    };
    let raw = (0.65f32 / 0.385).ln();
    let placed = side(&LightingChange::new(&input, &relit, res, high), high);
    let by_rule = side(
        &LightingChange::new(&input, &relit, res, FacePlace::default()),
        high,
    );
    assert!(placed > 0.8 * raw, "{placed} of {raw}");
    assert!(by_rule < 0.5 * raw, "{by_rule} of {raw}");
}

#[test]
fn a_lights_side_passes_nearly_whole_over_the_face_box() {
    // A key light from the image's left, its edge down the face's middle as
    // a nose's shadow falls: the network's output 30% brighter than its grey
    // input left of the face's centre line and 30% darker right of it. The
    // side a user sees, the face box's left half less its right half in mean
    // log gain, keeps nearly all of the network's (0.89 of it): blurred over
    // four network pixels, as the face's shading once was, it kept 0.76.
    let res = 96;
    let n = res * res;
    let face = FacePlace::default();
    let middle = (face.centre[0] * res as f32) as usize;
    let input = vec![0.5f32; 3 * n];
    let relit: Vec<f32> = (0..3 * n)
        .map(|i| if i % res < middle { 0.65 } else { 0.385 })
        .collect();
    let change = LightingChange::new(&input, &relit, res, face);
    let (mut sums, mut counts) = ([0f32; 2], [0f32; 2]);
    for i in 0..n {
        let u = [i % res, i / res].map(|v| (v as f32 + 0.5) / res as f32);
        let (dx, dy) = (u[0] - face.centre[0], u[1] - face.centre[1]);
        if dx.abs() < face.height / 2.0 && dy.abs() < face.height / 2.0 {
            let half = usize::from(dx > 0.0);
            sums[half] += (0..3).map(|c| change.log_gain[c][i]).sum::<f32>() / 3.0;
            counts[half] += 1.0;
        }
    }
    let side = sums[0] / counts[0] - sums[1] / counts[1];
    let raw = (0.65f32 / 0.385).ln();
    assert!(side > 0.85 * raw, "{side} of {raw}");
}

#[test]
fn identity_change_keeps_the_frame() {
    let mut data = rgb_frame(64, 64, |x, y| {
        [(x * 4) as u8, (y * 4) as u8, ((x + y) * 2) as u8]
    });
    let before = data.clone();
    let crop = Crop {
        x: 0,
        y: 0,
        size: 64,
    };
    let input = sample_crop(&Frame::packed_rgb(&data, 64, 64), crop, 16);
    let change = LightingChange::new(&input, &input, 16, FacePlace::default());
    let mut fm = FrameMut {
        format: PixelFormat::Rgb,
        width: 64,
        height: 64,
        planes: [(&mut data, 192), (&mut [], 0), (&mut [], 0)],
        matrix: YuvMatrix::BT601_LIMITED,
    };
    change.apply(&mut fm, crop, 0);
    assert_eq!(data, before);
}

// The fast crop and paste against the reference, their former selves.

const FORMATS: [PixelFormat; 9] = [
    PixelFormat::I420,
    PixelFormat::Nv12,
    PixelFormat::Y444,
    PixelFormat::Rgba,
    PixelFormat::Bgra,
    PixelFormat::Rgbx,
    PixelFormat::Bgrx,
    PixelFormat::Rgb,
    PixelFormat::Bgr,
];

/// Frame sizes, odd ones among them, and a portrait one.
const SIZES: [(usize, usize); 4] = [(64, 48), (37, 29), (50, 50), (23, 61)];

/// xorshift32: deterministic noise without a dependency.
struct Noise(u32);

impl Noise {
    fn next(&mut self) -> u32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        self.0
    }

    fn byte(&mut self) -> u8 {
        (self.next() >> 24) as u8
    }

    /// Uniform in [lo, hi).
    fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * (self.next() >> 8) as f32 / (1 << 24) as f32
    }
}

/// Random bytes of a frame of `format`, padding included.
fn random_frame(format: PixelFormat, width: usize, height: usize, noise: &mut Noise) -> OwnedFrame {
    OwnedFrame::new(format, (width, height), 5, YuvMatrix::BT709_LIMITED, || {
        noise.byte()
    })
}

/// Every byte of every plane, in order.
fn bytes(frame: &OwnedFrame) -> Vec<u8> {
    frame.planes.iter().flat_map(|(d, _)| d.clone()).collect()
}

/// Crops touching no edge, each edge and each corner, with odd and even
/// positions and sizes, and the element's own.
fn crops(width: usize, height: usize) -> Vec<Crop> {
    let short = width.min(height);
    let c = short / 2 + 1;
    let crop = |x, y, size| Crop { x, y, size };
    vec![
        Crop::centred(width, height, 0.5, 0.5, 1.0),
        crop(0, 0, short * 2 / 3),
        crop(width - c, height - c, c),
        crop(3, 5, short / 2 - 1),
        crop(0, (height - c) / 2 + 1, c),
        crop(width - c, 0, c),
        crop(width - short, height - short, short),
    ]
}

/// A change from random network images, or (`wild`) random gains far beyond
/// real ones, so the clamping at 0 and 255 is exercised too.
fn random_change(res: usize, wild: bool, noise: &mut Noise) -> LightingChange {
    let n = res * res;
    let mut image = |lo, hi| -> Vec<f32> { (0..3 * n).map(|_| noise.uniform(lo, hi)).collect() };
    if !wild {
        let (input, relit) = (image(0.0, 1.0), image(0.0, 1.0));
        return LightingChange::new(&input, &relit, res, FacePlace::default());
    }
    let log_gain = image(-3.0, 3.0);
    LightingChange {
        res,
        log_gain: [0, 1, 2].map(|c| log_gain[c * n..(c + 1) * n].to_vec()),
        face: FacePlace::default(),
    }
}

/// Applies `change` with the fast paste and the reference to copies of
/// `buffers` and says whether they came out byte for byte the same, and how
/// many bytes the paste changed.
fn paste_both(
    buffers: &OwnedFrame,
    change: &LightingChange,
    crop: Crop,
    feather: usize,
) -> (bool, usize) {
    let copy = || OwnedFrame {
        planes: buffers.planes.clone(),
        ..*buffers
    };
    let (mut fast, mut old) = (copy(), copy());
    change.apply(&mut fast.frame_mut(), crop, feather);
    reference::apply(change, &mut old.frame_mut(), crop, feather);
    let (fast, old, before) = (bytes(&fast), bytes(&old), bytes(buffers));
    let changed = fast.iter().zip(&before).filter(|(a, b)| a != b).count();
    (fast == old, changed)
}

#[test]
fn paste_matches_the_reference_byte_for_byte() {
    let mut noise = Noise(0x5eed);
    let (mut cases, mut changed) = (0, 0);
    for format in FORMATS {
        for (width, height) in SIZES {
            let buffers = random_frame(format, width, height, &mut noise);
            for crop in crops(width, height) {
                // Network resolutions below and above the crop's: 40 > every
                // crop here but the largest.
                for res in [16, 7, 40] {
                    let change = random_change(res, cases % 2 == 1, &mut noise);
                    for feather in [0, 3, 100] {
                        let (same, n) = paste_both(&buffers, &change, crop, feather);
                        assert!(
                            same,
                            "{format:?} {width}x{height} {crop:?} res {res} feather {feather}"
                        );
                        cases += 1;
                        changed += n;
                    }
                }
            }
        }
    }
    // Not vacuous: the changes do change the frames.
    assert!(
        changed > cases * 100,
        "{changed} bytes changed in {cases} cases"
    );
}

#[test]
fn paste_matches_the_reference_at_full_size() {
    // Tall enough that each half is pasted on a thread of its own; the odd
    // size splits a chroma row's neighbours and ends in a short one.
    let mut noise = Noise(0xface);
    for format in FORMATS {
        for (width, height) in [(1280, 720), (853, 481)] {
            let buffers = random_frame(format, width, height, &mut noise);
            let crop = Crop::centred(width, height, 0.5, 0.5, 1.0);
            let change = random_change(96, false, &mut noise);
            assert!(
                paste_both(&buffers, &change, crop, 43).0,
                "{format:?} {width}x{height}"
            );
        }
    }
}

#[test]
fn a_network_output_that_is_not_finite_changes_nothing_there() {
    // The policy passes such frames through, but the change must not turn
    // the frame black or into noise if one gets here: a gain that is not
    // finite counts as none.
    let mut noise = Noise(0xbad);
    let res = 16;
    let input: Vec<f32> = (0..3 * res * res)
        .map(|_| noise.uniform(0.2, 0.8))
        .collect();
    let relit = vec![f32::NAN; input.len()];
    let change = LightingChange::new(&input, &relit, res, FacePlace::default());
    for format in FORMATS {
        let buffers = random_frame(format, 37, 29, &mut noise);
        for crop in crops(37, 29) {
            let (same, changed) = paste_both(&buffers, &change, crop, 3);
            assert!(same, "{format:?} {crop:?}");
            assert_eq!(changed, 0, "{format:?} {crop:?}");
        }
    }
}

/// The crop sums in another order than the reference (vertically first), so
/// its floats may differ in the last bits: by at most 4.8e-7 (a few units in
/// the last place of values up to 1) in every case below, in about a quarter
/// of the floats.
const CROP_TOLERANCE: f32 = 1e-6;

#[test]
fn crop_matches_the_reference_within_rounding() {
    let mut noise = Noise(0xc409);
    let mut worst = 0f32;
    let mut check = |frame: &Frame, crop: Crop, res: usize| {
        let (fast, old) = (
            sample_crop(frame, crop, res),
            reference::sample_crop(frame, crop, res),
        );
        assert_eq!(fast.len(), old.len());
        for (a, b) in fast.iter().zip(&old) {
            worst = worst.max((a - b).abs());
        }
    };
    for format in FORMATS {
        for (width, height) in SIZES {
            let buffers = random_frame(format, width, height, &mut noise);
            for crop in crops(width, height) {
                for res in [16, 7, 40] {
                    check(&buffers.frame(), crop, res);
                }
            }
        }
        // Full size, where each output sample sums many bytes: about 8 a side
        // at 720p and 23 at 2160p.
        for (width, height) in [(1280, 720), (3840, 2160)] {
            let buffers = random_frame(format, width, height, &mut noise);
            check(
                &buffers.frame(),
                Crop::centred(width, height, 0.5, 0.5, 1.0),
                96,
            );
        }
    }
    assert!(worst <= CROP_TOLERANCE, "largest difference {worst:e}");
}

#[test]
fn a_crop_split_between_threads_is_the_crop_on_one_bit_for_bit() {
    let mut noise = Noise(0x5b1);
    for format in FORMATS {
        let buffers = random_frame(format, 1280, 720, &mut noise);
        let frame = buffers.frame();
        let crop = Crop::centred(1280, 720, 0.4, 0.5, 1.0);
        assert!(crop.size >= SPLIT_CROP, "{crop:?} is not split");
        // An odd resolution: the halves differ by a row.
        for res in [96, 97] {
            let (split, whole) = (
                sample_crop(&frame, crop, res),
                sample_crop_split(&frame, crop, res, res),
            );
            let bits = |v: &[f32]| -> Vec<u32> { v.iter().map(|x| x.to_bits()).collect() };
            assert!(bits(&split) == bits(&whole), "{format:?} at {res}");
        }
    }
}

#[test]
fn rounding_matches_f32_round() {
    let check = |x: f32| {
        let expected = x.round().clamp(0.0, 255.0) as u8;
        assert_eq!(round_to_u8(x), expected, "{x:e} ({:#x})", x.to_bits());
    };
    for x in [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::MAX,
        f32::MIN,
        -0.0,
    ] {
        check(x);
    }
    // Every float within 4096 steps of each whole and half number around
    // [0, 255], where rounding and clamping change.
    for twice in -4..=516 {
        let (mut up, mut down) = (twice as f32 / 2.0, twice as f32 / 2.0);
        for _ in 0..4096 {
            check(up);
            check(down);
            (up, down) = (up.next_up(), down.next_down());
        }
    }
    let mut noise = Noise(0x70d);
    for _ in 0..1_000_000 {
        check(f32::from_bits(noise.next()));
        check(noise.uniform(-2.0, 258.0));
    }
}

#[test]
fn layouts_match_the_reference() {
    let mut noise = Noise(0x1a7);
    for format in FORMATS {
        assert_eq!(format.packed(), reference::packed(format), "{format:?}");
        if format.is_yuv() {
            let buffers = random_frame(format, 37, 29, &mut noise);
            let frame = buffers.frame();
            for (x, y) in [(0, 0), (36, 28), (5, 8), (17, 3)] {
                assert_eq!(
                    format.chroma_at(&frame.planes, x, y),
                    reference::chroma_at(format, &frame.planes, x, y),
                    "{format:?} ({x}, {y})"
                );
            }
        }
    }
}

#[test]
fn every_build_of_the_inner_loops_agrees() {
    // The tests above run whichever build of `gain_row`, `chroma_change` and `weighted_sum` the
    // CPU takes (AVX2 or AVX-512); this holds the others to it.
    let mut noise = Noise(0xa1b2);
    let n = 1000 + 7;
    let mut map = |lo, hi| -> Vec<f32> { (0..n).map(|_| noise.uniform(lo, hi)).collect() };
    let (mut top, mut bottom) = (map(0.0, MAX_GAIN), map(0.0, MAX_GAIN));
    bottom[5] = f32::NAN;
    bottom[17] = f32::INFINITY;
    bottom[20] = -0.0;
    top[9] = f32::NEG_INFINITY;
    let mut dither: Vec<f32> = (0..n).map(|x| dither(x, 1)).collect();
    dither[3] = f32::NAN;
    dither[12] = -0.5;
    let row: Vec<u8> = (0..n).map(|_| noise.byte()).collect();
    let (mut chosen, mut portable) = (row.clone(), row.clone());
    gain_row(&mut chosen, 0.3, (&top, &bottom), 1.7, &dither);
    gain_row_portable(&mut portable, 0.3, (&top, &bottom), 1.7, &dither);
    assert_eq!(chosen, portable);
    assert_ne!(chosen, row);
    // Every value exactly half a level above a whole one: rounded away from zero.
    let (ones, halves) = (vec![1.0; n], vec![0.5; n]);
    let (mut chosen, mut portable) = (row.clone(), row.clone());
    gain_row(&mut chosen, 0.3, (&ones, &ones), 0.0, &halves);
    gain_row_portable(&mut portable, 0.3, (&ones, &ones), 0.0, &halves);
    assert_eq!(chosen, portable);
    let up: Vec<u8> = row.iter().map(|&b| b.saturating_add(1)).collect();
    assert_eq!(chosen, up);

    // The chroma change of a YUV row.
    let mut map = |lo, hi| -> Vec<f32> { (0..n).map(|_| noise.uniform(lo, hi)).collect() };
    let gains = [0; 6].map(|_| map(0.0, MAX_GAIN));
    let (luma, cb, cr) = (map(0.0, 255.0), map(0.0, 255.0), map(0.0, 255.0));
    let rows = (
        [&gains[0][..], &gains[1], &gains[2]],
        [&gains[3][..], &gains[4], &gains[5]],
    );
    let yuv = YuvChange::new(YuvMatrix::BT709_LIMITED);
    let run = |portable: bool| {
        let (mut cb, mut cr, mut extra) = (cb.clone(), cr.clone(), vec![0.0; n]);
        let chroma = (&mut cb[..], &mut cr[..]);
        if portable {
            chroma_change_portable(&yuv, 0.3, rows, &luma, chroma, &mut extra);
        } else {
            chroma_change(&yuv, 0.3, rows, &luma, chroma, &mut extra);
        }
        [cb, cr, extra].map(|v| v.into_iter().map(f32::to_bits).collect::<Vec<_>>())
    };
    assert_eq!(run(false), run(true));

    // A luma row's chroma terms, doubled and dithered, with a short last block.
    let mut terms = map(-40.0, 40.0);
    terms.truncate(n.div_ceil(2));
    let (mut chosen, mut portable) = (vec![0.0; n], vec![0.0; n]);
    spread::<2>(&mut chosen, &terms, &dither);
    spread_portable::<2>(&mut portable, &terms, &dither);
    let bits = |v: &[f32]| -> Vec<u32> { v.iter().map(|x| x.to_bits()).collect() };
    assert_eq!(bits(&chosen), bits(&portable));
    assert_eq!(
        chosen[n - 1].to_bits(),
        (terms[n / 2] + dither[n - 1]).to_bits()
    );
    // A plane's own row of chroma, rounded: every value the rounding treats apart.
    let mut values = map(-10.0, 270.0);
    values[..6].copy_from_slice(&[f32::NAN, -0.0, 0.5, 1.5, f32::INFINITY, 254.5]);
    let mut chosen = vec![0u8; n];
    write_lane::<1>(&mut chosen, 0, &values);
    let rounded: Vec<u8> = values.iter().map(|&v| round_to_u8(v)).collect();
    assert_eq!(chosen, rounded);
    assert_eq!(chosen[..6], [0, 0, 1, 2, 255, 255]);

    // Rows long enough for whole blocks and a tail.
    let rows: Vec<&[u8]> = row.chunks_exact(n / 3).collect();
    let weights = [0.25, 0.5, 0.25];
    let (mut chosen, mut portable) = (vec![0.0; n / 3], vec![0.0; n / 3]);
    weighted_sum(&mut chosen, &rows, &weights);
    weighted_sum_portable(&mut portable, &rows, &weights);
    assert_eq!(bits(&chosen), bits(&portable));
    // Every build this CPU can run, not only the one chosen, each into fresh sums.
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut built = vec![0.0; n / 3];
            // SAFETY: the CPU has AVX2, checked just above.
            unsafe { weighted_sum_avx2(&mut built, &rows, &weights) };
            assert_eq!(bits(&built), bits(&portable), "AVX2");
        }
        if has_avx512() {
            let mut built = vec![0.0; n / 3];
            // SAFETY: the CPU has AVX-512 F, BW and VL, checked just above.
            unsafe { weighted_sum_avx512(&mut built, &rows, &weights) };
            assert_eq!(bits(&built), bits(&portable), "AVX-512");
        }
    }
}

// The change as a gain field over the frame.

/// The change `relit = gain · input` (per channel) of the crop of an RGB frame,
/// applied around the crop with `feather`: the frame before and after.
fn gained(
    (w, h): (usize, usize),
    pixel: impl Fn(usize, usize) -> [u8; 3],
    crop: Crop,
    feather: usize,
    gain: impl Fn(usize, usize) -> f32,
) -> (Vec<u8>, Vec<u8>) {
    let before = rgb_frame(w, h, pixel);
    let res = 32;
    let input = sample_crop(&Frame::packed_rgb(&before, w, h), crop, res);
    let relit: Vec<f32> = input
        .iter()
        .enumerate()
        .map(|(i, v)| v * gain(i / (res * res), i % (res * res)))
        .collect();
    let mut after = before.clone();
    let mut fm = FrameMut {
        format: PixelFormat::Rgb,
        width: w,
        height: h,
        planes: [(&mut after, w * 3), (&mut [], 0), (&mut [], 0)],
        matrix: YuvMatrix::BT601_LIMITED,
    };
    LightingChange::new(&input, &relit, res, FacePlace::default()).apply(&mut fm, crop, feather);
    (before, after)
}

/// ln(after / before) of pixel (`x`, `y`)'s green byte in two RGB frames `w` wide.
fn green_log_ratio(before: &[u8], after: &[u8], w: usize, x: usize, y: usize) -> f32 {
    let i = (y * w + x) * 3 + 1;
    (after[i] as f32 / before[i] as f32).ln()
}

/// The largest step of `ratio` between neighbouring pixels, across or down.
fn steepest_step((w, h): (usize, usize), ratio: impl Fn(usize, usize) -> f32) -> f32 {
    let mut steepest = 0f32;
    for y in 1..h {
        for x in 1..w {
            steepest = steepest
                .max((ratio(x, y) - ratio(x - 1, y)).abs())
                .max((ratio(x, y) - ratio(x, y - 1)).abs());
        }
    }
    steepest
}

#[test]
fn the_change_fades_out_smoothly_beyond_the_crop() {
    let (w, h) = (240, 160);
    let crop = Crop {
        x: 90,
        y: 50,
        size: 60,
    };
    let feather = 60;
    let (before, after) = gained((w, h), |_, _| [100; 3], crop, feather, |_, _| 1.5);
    let ratio = |x: usize, y: usize| green_log_ratio(&before, &after, w, x, y);
    // Whole at the centre: the network's gain (with its ε of 0.02) on the
    // frame's value plus two levels, dithered by less than half a level.
    let i = 100.0 / 255.0;
    let gain = (1.5 * i + 0.02) / (i + 0.02);
    let centre = after[(80 * w + 120) * 3 + 1] as f32;
    let expected = gain * 102.0 - 2.0;
    assert!(
        (centre - expected).abs() <= 1.0,
        "{centre} at the centre, not {expected}"
    );
    // Nothing beyond the fade round head and shoulders (a grid cell, 3.75
    // pixels, of interpolation aside); something at the crop's corners and
    // beyond its sides.
    let silhouette = Silhouette::new(crop, FacePlace::default(), feather as f32);
    for y in 0..h {
        for x in 0..w {
            if silhouette.distance([x as f32 + 0.5, y as f32 + 0.5]) > feather as f32 + 5.0 {
                assert_eq!(ratio(x, y), 0.0, "({x}, {y})");
            }
        }
    }
    assert!(
        ratio(91, 51) > 0.1,
        "at the crop's corner: {}",
        ratio(91, 51)
    );
    assert!(
        ratio(70, 80) > 0.1,
        "beyond the crop's side: {}",
        ratio(70, 80)
    );
    // No step anywhere: a smoothstep of ln 1.5 over the feather rises at most
    // 1.5 · ln 1.5 / feather a pixel (0.015), and dither and rounding move
    // each pixel by up to a level (0.01) either way. A box would step by 0.4.
    let steepest = steepest_step((w, h), ratio);
    assert!(steepest < 0.036, "steepest step {steepest}");
}

#[test]
fn the_change_runs_down_the_shoulders_and_not_beside_them() {
    // A face in the frame's top quarter, the rest of the frame below it: the
    // light on a face falls on its neck and shoulders too, so the change
    // goes on down the body, whole, however far below the crop; beside the
    // shoulders it fades out as it does round the head, with no step.
    let (w, h) = (480, 320);
    let crop = Crop {
        x: 210,
        y: 30,
        size: 60,
    };
    let feather = 60;
    let (before, after) = gained((w, h), |_, _| [100; 3], crop, feather, |_, _| 1.5);
    let ratio = |x: usize, y: usize| green_log_ratio(&before, &after, w, x, y);
    let whole = ratio(240, 60);
    assert!(whole > 0.3, "at the face: {whole}");
    // 200 pixels below the crop, 11 face heights below the face, where a
    // disc round the head has long faded out.
    for x in [225, 240, 255] {
        let r = ratio(x, 300);
        assert!((r - whole).abs() < 0.02, "({x}, 300): {r} against {whole}");
    }
    // Beside the shoulders (the face 20.7 pixels high, the body 1.3 face
    // heights either side of its middle) and a feather beyond: nothing.
    for x in (0..140).chain(341..w) {
        assert_eq!(ratio(x, 300), 0.0, "({x}, 300)");
    }
    let steepest = steepest_step((w, h), ratio);
    assert!(steepest < 0.036, "steepest step {steepest}");
    // With a narrow fade, the neck between chin and shoulders is whole too:
    // head and body are one shape, not two with a gap between.
    let (before, after) = gained((w, h), |_, _| [100; 3], crop, 6, |_, _| 1.5);
    let neck = green_log_ratio(&before, &after, w, 240, 79);
    assert!(
        (neck - whole).abs() < 0.02,
        "at the neck: {neck} against {whole}"
    );
}

#[test]
fn the_silhouette_joins_head_neck_and_shoulders_wherever_the_face_sits() {
    // The crop rule's face, a large face low in its crop and a small one
    // high in it (crops moved to stay inside the frame).
    let crop = Crop {
        x: 100,
        y: 100,
        size: 120,
    };
    let places = [
        FacePlace::default(),
        FacePlace {
            centre: [0.45, 0.7],
            height: 0.5,
        },
        FacePlace {
            centre: [0.55, 0.3],
            height: 0.25,
        },
    ];
    for face in places {
        let s = Silhouette::new(crop, face, 0.0);
        let centre = [160.0, 160.0];
        let face_centre = [
            100.0 + 120.0 * face.centre[0],
            100.0 + 120.0 * face.centre[1],
        ];
        let face_height = 120.0 * face.height;
        // From the head's centre to the face's, then down to three face
        // heights below it: inside all the way.
        for step in 0..=100 {
            let t = step as f32 / 100.0;
            let on_line = [
                centre[0] + t * (face_centre[0] - centre[0]),
                centre[1] + t * (face_centre[1] + 3.0 * face_height - centre[1]),
            ];
            assert!(
                s.distance(on_line) <= 0.0,
                "{face:?}: {on_line:?} is outside"
            );
        }
        // Beside the shoulders, past the band's half width: outside.
        let beside = [
            face_centre[0] + 1.5 * face_height,
            face_centre[1] + 3.0 * face_height,
        ];
        assert!(s.distance(beside) > 0.0, "{face:?}: {beside:?} is inside");
        // The bounds hold everything within a feather of the shape.
        let feather = 30.0;
        let s = Silhouette::new(crop, face, feather);
        let (low, high) = s.bounds();
        for y in -200..600 {
            for x in -200..600 {
                let p = [x as f32, y as f32];
                if s.distance(p) < feather {
                    assert!(
                        p[0] >= low[0] && p[0] <= high[0] && p[1] >= low[1] && p[1] <= high[1],
                        "{face:?}: {p:?} within the fade lies outside {low:?}..{high:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn the_dither_stays_off_the_face_and_covers_the_room() {
    // A dark flat frame brightened evenly: over the face a smooth change
    // rounds to one value (a dither there would grain the skin's dark
    // pixels in colour); in the room round it, the same change is dithered,
    // so a smooth change over a dark wall does not round to bands.
    let (w, h) = (240, 160);
    let crop = Crop {
        x: 90,
        y: 50,
        size: 60,
    };
    // A fade far wider than the frame: the change is even over all of it.
    let (_, after) = gained((w, h), |_, _| [4; 3], crop, 4000, |_, _| 1.5);
    let green = |x: usize, y: usize| after[(y * w + x) * 3 + 1];
    let inner = INNER_RADIUS * 60.0;
    let mut on_face = std::collections::BTreeSet::new();
    for y in 0..h {
        for x in 0..w {
            if (x as f32 + 0.5 - 120.0).hypot(y as f32 + 0.5 - 80.0) < 0.85 * inner {
                on_face.insert(green(x, y));
            }
        }
    }
    assert_eq!(on_face.len(), 1, "the face's values: {on_face:?}");
    assert!(on_face.first() > Some(&4), "the face is not brightened");
    // One 4 x 4 block of the pattern, twice the inner radius from the centre.
    let in_room: std::collections::BTreeSet<u8> = (78..82)
        .flat_map(|y| (148..152).map(move |x| (x, y)))
        .map(|(x, y)| green(x, y))
        .collect();
    assert!(in_room.len() > 1, "the room's block: {in_room:?}");
}

#[test]
fn colour_noise_from_the_network_stays_out_of_the_frame() {
    // Each network pixel's colour off by up to ±15%, as the network's own
    // noise: the frame should take the mean tint, not the blotches.
    let (w, h) = (160, 160);
    let crop = Crop {
        x: 16,
        y: 16,
        size: 128,
    };
    let mut noise = Noise(0xc010);
    let jitter: Vec<f32> = (0..3 * 32 * 32)
        .map(|_| noise.uniform(-0.15, 0.15))
        .collect();
    let tint = [1.3, 1.1, 0.9];
    let (_, after) = gained(
        (w, h),
        |_, _| [120; 3],
        crop,
        20,
        |c, i| tint[c] * (1.0 + jitter[c * 32 * 32 + i]),
    );
    // Where the change is whole (within the inner circle), each channel less
    // the pixel's mean.
    let mut spread = [(f32::MAX, f32::MIN); 3];
    for y in 48..112 {
        for x in 48..112 {
            if (x as f32 + 0.5 - 80.0).hypot(y as f32 + 0.5 - 80.0) > INNER_RADIUS * 128.0 {
                continue;
            }
            let p = &after[(y * w + x) * 3..(y * w + x) * 3 + 3];
            let mean = p.iter().map(|&v| v as f32).sum::<f32>() / 3.0;
            for c in 0..3 {
                let d = p[c] as f32 - mean;
                spread[c] = (spread[c].0.min(d), spread[c].1.max(d));
            }
        }
    }
    for (c, (lo, hi)) in spread.into_iter().enumerate() {
        assert!(
            hi - lo <= 4.0,
            "channel {c} colour spread {lo}..{hi} levels"
        );
    }
    // And the tint itself came through: red above blue by about 0.4 · 125.
    let p = &after[(80 * w + 80) * 3..(80 * w + 80) * 3 + 3];
    assert!(p[0] as i32 - p[2] as i32 > 40, "{p:?}");
}

#[test]
fn yuv_and_rgb_frames_take_the_same_change() {
    // A coloured frame with dark, hair-like stripes across bright skin, and
    // the same frame as Y444, relit with a warm tint: each YUV pixel must take
    // the colour the RGB paste gives it, to within the rounding of the
    // conversions, the dark pixels too.
    let (w, h) = (96, 80);
    let matrix = YuvMatrix::BT709_LIMITED;
    let pixel = |x: usize, y: usize| {
        if (x / 3 + y / 5).is_multiple_of(4) {
            [20 + (x % 7) as u8, 14, 10 + (y % 5) as u8]
        } else {
            [110 + x as u8 / 2, 150 - y as u8, 90 + (x + y) as u8 / 3]
        }
    };
    let crop = Crop {
        x: 18,
        y: 10,
        size: 60,
    };
    let gain = |c: usize, _| [1.4, 1.1, 0.8][c];
    let (_, rgb_after) = gained((w, h), pixel, crop, 10, gain);

    let mut yuv = OwnedFrame::new(PixelFormat::Y444, (w, h), 0, matrix, || 0);
    for y in 0..h {
        for x in 0..w {
            let p = pixel(x, y).map(|v| v as f32 / 255.0);
            for (plane, v) in yuv.planes.iter_mut().zip(matrix.from_rgb(p)) {
                plane.0[y * w + x] = v.round() as u8;
            }
        }
    }
    let res = 32;
    let input = sample_crop(&yuv.frame(), crop, res);
    let relit: Vec<f32> = input
        .iter()
        .enumerate()
        .map(|(i, v)| v * gain(i / (res * res), 0))
        .collect();
    // Over the dark stripes and elsewhere: the mean of each channel's
    // difference between the YUV frame's colours and the RGB frame's, and
    // the largest difference, in levels.
    let compare = |yuv: &OwnedFrame, rgb: &dyn Fn(usize, usize, usize) -> u8| {
        let mut sums = [[0f32; 3]; 2];
        let mut counts = [0f32; 2];
        let mut worst = 0f32;
        for y in 0..h {
            for x in 0..w {
                let dark = usize::from(pixel(x, y)[0] < 50);
                let yuv_at = |p: usize| yuv.planes[p].0[y * w + x] as f32;
                let back = matrix.to_rgb(yuv_at(0), yuv_at(1), yuv_at(2));
                for (c, v) in back.into_iter().enumerate() {
                    // As a decoder shows it.
                    let d = (v * 255.0).clamp(0.0, 255.0) - rgb(x, y, c) as f32;
                    sums[dark][c] += d;
                    worst = worst.max(d.abs());
                }
                counts[dark] += 1.0;
            }
        }
        let means = [0, 1].map(|k| sums[k].map(|s| s / counts[k]));
        (means, worst)
    };
    let (_, before) = compare(&yuv, &|x, y, c| pixel(x, y)[c]);
    LightingChange::new(&input, &relit, res, FacePlace::default()).apply(
        &mut yuv.frame_mut(),
        crop,
        10,
    );
    let (means, after) = compare(&yuv, &|x, y, c| rgb_after[(y * w + x) * 3 + c]);
    // Each paste rounds and dithers, by up to a level in each plane, which
    // the conversion back to RGB spreads over the channels: three levels at
    // most, none on average (3.0 and under 0.07 when written). The chroma
    // change taken from the region's smoothed colour rather than each pixel's
    // (the paste before) missed by 23.7 levels, and on average by 3.2 (red)
    // on the dark stripes and 1.5 (blue) elsewhere.
    assert!(
        after <= before + 3.0,
        "YUV and RGB differ by {after} levels, {before} before the change"
    );
    for (region, means) in ["elsewhere", "on the dark stripes"].iter().zip(means) {
        for (c, mean) in means.into_iter().enumerate() {
            assert!(
                mean.abs() < 0.5,
                "{region}, channel {c} is off by {mean} levels on average"
            );
        }
    }
}
