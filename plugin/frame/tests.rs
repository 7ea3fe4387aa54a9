use super::*;
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
    let change = LightingChange::new(
        &input,
        &input,
        16,
        PixelFormat::Rgb,
        YuvMatrix::BT601_LIMITED,
    );
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

/// A change from random network images, or (`wild`) random maps that leave
/// the range of real ones so the clamping at 0 and 255 is exercised too.
fn random_change(res: usize, format: PixelFormat, wild: bool, noise: &mut Noise) -> LightingChange {
    let n = res * res;
    let mut image = |lo, hi| -> Vec<f32> { (0..3 * n).map(|_| noise.uniform(lo, hi)).collect() };
    if !wild {
        let (input, relit) = (image(0.0, 1.0), image(0.0, 1.0));
        return LightingChange::new(&input, &relit, res, format, YuvMatrix::BT709_LIMITED);
    }
    let (base, input) = (image(-60.0, 320.0), image(-60.0, 320.0));
    let channels = |v: Vec<f32>| [0, 1, 2].map(|c| v[c * n..(c + 1) * n].to_vec());
    LightingChange {
        res,
        base: channels(base),
        input: channels(input),
        gain: [0, 1, 2].map(|_| (0..n).map(|_| noise.uniform(0.0, MAX_GAIN)).collect()),
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
                    let change = random_change(res, format, cases % 2 == 1, &mut noise);
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
    let mut noise = Noise(0xface);
    for format in FORMATS {
        let buffers = random_frame(format, 1280, 720, &mut noise);
        let crop = Crop::centred(1280, 720, 0.5, 0.5, 1.0);
        let change = random_change(96, format, false, &mut noise);
        assert!(paste_both(&buffers, &change, crop, 43).0, "{format:?}");
    }
}

#[test]
fn paste_matches_the_reference_where_the_maps_are_not_finite() {
    // The network can put out NaN; bytes under it become 0 where the change
    // applies and stay as they were where the fade is zero.
    let mut noise = Noise(0xbad);
    for format in FORMATS {
        let buffers = random_frame(format, 37, 29, &mut noise);
        let mut change = random_change(7, format, false, &mut noise);
        change.base[0][3] = f32::NAN;
        change.base[2][20] = f32::INFINITY;
        change.input[1][30] = f32::NEG_INFINITY;
        change.gain[0][9] = f32::NAN;
        // Under the first chroma column, which has zero fade with an odd crop.
        change.gain[1][7] = f32::NAN;
        for crop in crops(37, 29) {
            for feather in [0, 3] {
                let (same, _) = paste_both(&buffers, &change, crop, feather);
                assert!(same, "{format:?} {crop:?} feather {feather}");
            }
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
fn both_builds_of_the_inner_loops_agree() {
    // The tests above run whichever build of `blend_row` and `weighted_sum` the
    // CPU takes (AVX2 on the build machine); this holds the other to it.
    let mut noise = Noise(0xa1b2);
    let n = 1000 + 7;
    let mut map = |lo, hi| -> Vec<f32> { (0..n).map(|_| noise.uniform(lo, hi)).collect() };
    let mut maps = || Maps {
        base: map(-60.0, 320.0),
        gain: map(0.0, MAX_GAIN),
        input: map(-60.0, 320.0),
    };
    let (top, mut bottom) = (maps(), maps());
    bottom.base[5] = f32::NAN;
    bottom.input[17] = f32::INFINITY;
    let wx = map(0.0, 1.0);
    let row: Vec<u8> = (0..n).map(|_| noise.byte()).collect();
    let (mut chosen, mut portable) = (row.clone(), row.clone());
    blend_row(&mut chosen, &wx, 0.7, 0.3, &top, &bottom);
    blend_row_portable(&mut portable, &wx, 0.7, 0.3, &top, &bottom);
    assert_eq!(chosen, portable);
    assert_ne!(chosen, row);

    // Rows long enough for whole blocks and a tail.
    let rows: Vec<&[u8]> = row.chunks_exact(n / 3).collect();
    let weights = [0.25, 0.5, 0.25];
    let (mut chosen, mut portable) = (vec![0.0; n / 3], vec![0.0; n / 3]);
    weighted_sum(&mut chosen, &rows, &weights);
    weighted_sum_portable(&mut portable, &rows, &weights);
    let bits = |v: Vec<f32>| -> Vec<u32> { v.into_iter().map(f32::to_bits).collect() };
    assert_eq!(bits(chosen), bits(portable));
}
