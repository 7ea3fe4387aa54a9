//! The denoiser's tests: noise and flicker taken out of a still face, no trail
//! behind a moving one, nothing changed beyond the fade, and the fast walk
//! held to the plain one's bytes in every format and build.

use super::motion::new_share;
#[cfg(target_arch = "x86_64")]
use super::motion::{over_noise_avx2, over_noise_plain};
use super::walk::EDGE_ROWS;
use super::*;
use crate::frame::gain_field::INNER_RADIUS;
use crate::frame::{OwnedFrame, YuvMatrix};

/// Normal noise from a fixed seed: a xorshift generator and Box-Muller.
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 40) as f32 + 0.5) / (1u64 << 24) as f32
    }

    fn normal(&mut self) -> f32 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f32::consts::TAU * b).cos()
    }
}

const SIZE: (usize, usize) = (96, 64);

/// Skin-like texture: fine stripes and blotches on a gradient, shifted right by `shift` pixels.
fn scene(x: usize, y: usize, shift: f32) -> f32 {
    let x = x as f32 - shift;
    let y = y as f32;
    110.0 + 0.3 * x + 12.0 * (x * 0.9).sin() * (y * 0.7).cos() + 8.0 * ((x + 2.0 * y) * 0.35).sin()
}

/// An RGB frame of the scene with noise of `sigma` levels in every channel.
fn noisy_rgb(shift: f32, sigma: f32, noise: &mut Noise) -> OwnedFrame {
    let mut f = OwnedFrame::new(PixelFormat::Rgb, SIZE, 0, YuvMatrix::BT601_LIMITED, || 0);
    let data = &mut f.planes[0].0;
    for y in 0..SIZE.1 {
        for x in 0..SIZE.0 {
            let clean = scene(x, y, shift);
            for c in 0..3 {
                let v = clean + 10.0 * c as f32 + sigma * noise.normal();
                data[(y * SIZE.0 + x) * 3 + c] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    f
}

/// A crop round the frame's middle, with [`WIDE`]: the denoising shows whole
/// (to a millionth) over the frame.
fn whole_frame() -> Crop {
    Crop {
        x: 0,
        y: 0,
        size: 96,
    }
}

/// A fade so wide that it barely begins within the frame.
const WIDE: usize = 1_000_000;

/// RMSE of the middle of frame `f` (8 pixels in from each edge) against the clean scene.
fn error(f: &OwnedFrame, shift: f32) -> f32 {
    let data = &f.planes[0].0;
    let (mut sum, mut n) = (0.0, 0);
    for y in 8..SIZE.1 - 8 {
        for x in 8..SIZE.0 - 8 {
            for c in 0..3 {
                let d =
                    data[(y * SIZE.0 + x) * 3 + c] as f32 - (scene(x, y, shift) + 10.0 * c as f32);
                sum += d * d;
                n += 1;
            }
        }
    }
    (sum / n as f32).sqrt()
}

/// RMSE of the change from frame `a` to frame `b` over their middle.
fn change(a: &OwnedFrame, b: &OwnedFrame) -> f32 {
    let (a, b) = (&a.planes[0].0, &b.planes[0].0);
    let (mut sum, mut n) = (0.0, 0);
    for y in 8..SIZE.1 - 8 {
        for x in 8..SIZE.0 - 8 {
            for c in 0..3 {
                let i = (y * SIZE.0 + x) * 3 + c;
                let d = b[i] as f32 - a[i] as f32;
                sum += d * d;
                n += 1;
            }
        }
    }
    (sum / n as f32).sqrt()
}

#[test]
fn a_still_face_loses_most_of_its_noise_and_flicker() {
    let mut denoiser = DetailDenoiser::default();
    let mut noise = Noise(7);
    let (mut before, mut after) = (Vec::new(), Vec::new());
    for _ in 0..30 {
        let raw = noisy_rgb(0.0, 4.0, &mut noise);
        let mut out = noisy_rgb(0.0, 0.0, &mut noise);
        out.planes[0].0.copy_from_slice(&raw.planes[0].0);
        denoiser.apply(&mut out.frame_mut(), whole_frame(), WIDE, 1.0);
        before.push(raw);
        after.push(out);
    }
    let last = |v: &[OwnedFrame]| (error(&v[29], 0.0), change(&v[28], &v[29]));
    let ((raw_error, raw_change), (error_after, change_after)) = (last(&before), last(&after));
    // The smooth band keeps a fifth of the noise; the detail about a third.
    assert!(
        error_after < 0.5 * raw_error && change_after < 0.4 * raw_change,
        "error {raw_error:.2} -> {error_after:.2}, change {raw_change:.2} -> {change_after:.2}"
    );
}

#[test]
fn the_first_frame_passes_as_it_is_and_so_after_a_reset() {
    let mut denoiser = DetailDenoiser::default();
    let mut noise = Noise(3);
    for round in 0..2 {
        // The first frame has no past; the second is filtered, against the
        // noise's level it teaches itself; a reset forgets both.
        for frame in 0..2 {
            let raw = noisy_rgb(0.0, 4.0, &mut noise);
            let mut out = noisy_rgb(0.0, 4.0, &mut noise);
            out.planes[0].0.copy_from_slice(&raw.planes[0].0);
            denoiser.apply(&mut out.frame_mut(), whole_frame(), WIDE, 1.0);
            let passed = out.planes[0].0 == raw.planes[0].0;
            assert_eq!(passed, frame == 0, "round {round}, frame {frame}");
        }
        denoiser.reset();
    }
}

#[test]
fn a_moving_face_leaves_no_trail() {
    let mut denoiser = DetailDenoiser::default();
    let mut noise = Noise(11);
    // Held still long enough to be filtered, then moving 2 pixels a frame.
    let mut worst: f32 = 0.0;
    let mut raw_worst: f32 = 0.0;
    for i in 0..30 {
        let shift = if i < 15 { 0.0 } else { 2.0 * (i - 14) as f32 };
        let mut f = noisy_rgb(shift, 2.0, &mut noise);
        raw_worst = raw_worst.max(error(&f, shift));
        denoiser.apply(&mut f.frame_mut(), whole_frame(), WIDE, 1.0);
        if i >= 15 {
            worst = worst.max(error(&f, shift));
        }
    }
    // A trail of the texture where it was would be an error of several levels.
    assert!(
        worst < 1.2 * raw_worst,
        "moving: error up to {worst:.2} against the input's {raw_worst:.2}"
    );
}

#[test]
fn nothing_changes_beyond_the_fade_or_at_strength_zero() {
    let mut noise = Noise(5);
    // A small crop in the corner: its disc and fade end well inside the frame.
    let crop = Crop {
        x: 0,
        y: 0,
        size: 32,
    };
    for strength in [1.0, 0.0] {
        let mut denoiser = DetailDenoiser::default();
        for _ in 0..5 {
            let raw = noisy_rgb(0.0, 4.0, &mut noise);
            let mut out = noisy_rgb(0.0, 0.0, &mut noise);
            out.planes[0].0.copy_from_slice(&raw.planes[0].0);
            denoiser.apply(&mut out.frame_mut(), crop, 8, strength);
            // The crop's centre, its inner radius and the fade: the farthest the
            // denoising reaches along either axis.
            let reach = 16 + (INNER_RADIUS * 32.0) as usize + 8;
            for y in 0..SIZE.1 {
                for x in 0..SIZE.0 {
                    if strength > 0.0 && x.max(y) <= reach {
                        continue;
                    }
                    let i = (y * SIZE.0 + x) * 3;
                    assert_eq!(
                        out.planes[0].0[i..i + 3],
                        raw.planes[0].0[i..i + 3],
                        "({x}, {y}) at strength {strength}"
                    );
                }
            }
        }
    }
}

/// Every plane's bytes of a frame.
type Planes = Vec<Vec<u8>>;

use crate::frame::ONE_FORMAT_OF_EACH_LAYOUT as FORMATS;

#[test]
fn every_format_is_denoised_and_padding_kept() {
    for format in FORMATS {
        let mut denoiser = DetailDenoiser::default();
        let mut noise = Noise(9);
        let mut last_change = 0.0;
        let mut raw_change = 0.0;
        let mut previous: Option<(Planes, Planes)> = None;
        for _ in 0..12 {
            // A still scene with noise in every byte, padding included.
            let mut pixel = 0usize;
            let mut f = OwnedFrame::new(format, SIZE, 4, YuvMatrix::BT601_LIMITED, || {
                pixel += 1;
                (120.0 + 20.0 * ((pixel % 97) as f32 * 0.3).sin() + 4.0 * noise.normal())
                    .round()
                    .clamp(0.0, 255.0) as u8
            });
            let raw: Vec<Vec<u8>> = f.planes.iter().map(|p| p.0.clone()).collect();
            denoiser.apply(&mut f.frame_mut(), whole_frame(), WIDE, 1.0);
            let out: Vec<Vec<u8>> = f.planes.iter().map(|p| p.0.clone()).collect();
            // Padding: the last 4 bytes of every row, and the X of BGRx.
            for (p, (plane, stride)) in f.planes.iter().enumerate() {
                for (row, bytes) in plane.chunks(*stride).enumerate() {
                    let pad = stride - 4..*stride;
                    assert_eq!(
                        bytes[pad.clone()],
                        raw[p][row * stride..][pad],
                        "{format:?}"
                    );
                    if format == PixelFormat::Bgrx {
                        for x in 0..SIZE.0 {
                            assert_eq!(bytes[x * 4 + 3], raw[p][row * stride + x * 4 + 3]);
                        }
                    }
                }
            }
            let rms = |a: &[Vec<u8>], b: &[Vec<u8>]| {
                let d: Vec<f32> = a[0]
                    .iter()
                    .zip(&b[0])
                    .map(|(x, y)| *x as f32 - *y as f32)
                    .collect();
                (d.iter().map(|v| v * v).sum::<f32>() / d.len() as f32).sqrt()
            };
            if let Some((pr, po)) = &previous {
                raw_change = rms(pr, &raw);
                last_change = rms(po, &out);
            }
            previous = Some((raw, out));
        }
        assert!(
            last_change < 0.6 * raw_change,
            "{format:?}: change {raw_change:.2} -> {last_change:.2}"
        );
    }
}

#[test]
fn the_share_of_a_new_frame_rises_smoothly_with_motion() {
    assert_eq!(new_share(0.0), STILL_SHARE);
    assert_eq!(new_share(STILL_RATIO), STILL_SHARE);
    assert_eq!(new_share(MOVING_RATIO), 1.0);
    assert_eq!(new_share(1e9), 1.0);
    let mut last = 0.0;
    for i in 0..100 {
        let s = new_share(i as f32 * 0.1);
        assert!(s >= last);
        last = s;
    }
}

/// A frame of `format` and `size`: the scene moving by `shift`, noise of
/// `sigma` levels, the same in every byte of a pixel but for an offset.
fn noisy_frame(
    format: PixelFormat,
    size: (usize, usize),
    shift: f32,
    sigma: f32,
    noise: &mut Noise,
) -> OwnedFrame {
    let mut i = 0usize;
    OwnedFrame::new(format, size, 3, YuvMatrix::BT601_LIMITED, || {
        i += 1;
        let (x, y) = (i % 211, i / 211);
        (scene(x, y, shift) - 20.0 + 7.0 * (i % 3) as f32 + sigma * noise.normal())
            .round()
            .clamp(0.0, 255.0) as u8
    })
}

#[test]
fn the_denoising_gives_the_bytes_and_detail_of_the_plain_one() {
    // Every format, sizes odd and even, a face that moves, grows, leaves the
    // frame's edge, fades, disappears and comes back, and a reset: the fast
    // denoiser must match the plain one's bytes exactly, and its filtered
    // detail and noise level, which carry into every later frame, in every
    // build of the walk this CPU can run (portable, AVX2, AVX-512; the noise
    // band's lookup picks its own build within each, tested below). Walked
    // whole on one thread, and split in halves on two, down to faces so small
    // that an area is a few rows and the rows copied beyond a half reach
    // past the area's edge.
    let mut fewest_rows = usize::MAX;
    let runs = FORMATS
        .into_iter()
        .flat_map(|f| [(f, SPLIT_FROM), (f, 0)])
        .flat_map(|run| {
            Build::available()
                .into_iter()
                .map(move |build| (run, build))
        });
    for ((format, split_from), build) in runs {
        for size in [(96, 64), (75, 53)] {
            let mut fast = DetailDenoiser {
                split_from,
                build,
                ..DetailDenoiser::default()
            };
            let mut plain = reference::ReferenceDenoiser::default();
            let mut noise = Noise(17);
            for i in 0..24 {
                let shift = if i < 8 { 0.0 } else { 1.5 * (i - 8) as f32 };
                let sigma = if i < 12 { 3.0 } else { 6.0 };
                let mut a = noisy_frame(format, size, shift, sigma, &mut noise);
                let mut b = noisy_frame(format, size, shift, sigma, &mut noise);
                for (pa, pb) in b.planes.iter_mut().zip(&a.planes) {
                    pa.0.copy_from_slice(&pb.0);
                }
                let crop = Crop {
                    x: [10, 10, 12, 0, 40, 60, 2, 30, 70][i % 9],
                    y: [8, 8, 9, 0, 20, 30, 4, 20, 40][i % 9],
                    size: [40, 40, 44, 64, 50, 36, 20, 4, 3][i % 9],
                };
                let strength = [1.0, 1.0, 0.7, 1.0, 0.0, 1.0, 0.3, 1.0][i % 8];
                if i == 17 {
                    fast.reset();
                    plain.reset();
                }
                fast.apply(&mut a.frame_mut(), crop, crop.size / 2, strength);
                plain.apply(&mut b.frame_mut(), crop, crop.size / 2, strength);
                for (p, (pa, pb)) in a.planes.iter().zip(&b.planes).enumerate() {
                    assert!(
                        pa.0 == pb.0,
                        "{format:?} {size:?} split from {split_from}, {build:?}: frame {i} plane {p}"
                    );
                }
                assert_eq!(fast.channels.len(), plain.channels.len());
                for (k, (f, p)) in fast.channels.iter().zip(&plain.channels).enumerate() {
                    if f.area[3] > 0 {
                        fewest_rows = fewest_rows.min(f.area[3]);
                    }
                    assert!(
                        f.detail == p.detail && f.noise == p.noise,
                        "{format:?} {size:?} split from {split_from}, {build:?}: frame {i} channel {k}: detail or noise"
                    );
                }
            }
        }
    }
    assert!(
        fewest_rows <= EDGE_ROWS,
        "the smallest area has {fewest_rows} rows: no half's copied rows reached past its edge"
    );
}

#[cfg(target_arch = "x86_64")]
#[test]
fn the_noise_band_lookup_in_avx2_is_the_plain_one_to_the_bit() {
    if !std::arch::is_x86_feature_detected!("avx2") {
        eprintln!("no AVX2 on this CPU: the vector lookup is not used");
        return;
    }
    // Smooth values on every band's edges and beyond both ends, a length that
    // leaves a tail, and ratios that are not all alike.
    let mut smooth: Vec<f32> = (0..=BANDS)
        .flat_map(|b| {
            let edge = (b * LEVELS) as f32;
            [edge - 0.5, edge - f32::EPSILON * edge, edge, edge + 0.25]
        })
        .collect();
    smooth.extend([-3.0, -0.0, 255.0, 300.0, 1e9]);
    let inverse: [f32; BANDS] = std::array::from_fn(|b| 1.0 / (1.5 + b as f32));
    let motion: Vec<f32> = (0..smooth.len()).map(|i| 0.3 + i as f32 * 0.7).collect();
    let (mut plain, mut avx2) = (motion.clone(), motion);
    over_noise_plain(&mut plain, &smooth, &inverse);
    // SAFETY: the CPU has AVX2, checked above.
    unsafe { over_noise_avx2(&mut avx2, &smooth, &inverse) };
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&avx2), bits(&plain));
    assert_ne!(smooth.len() % 8, 0, "a tail past the whole vectors");
}
