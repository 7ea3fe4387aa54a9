//! The motion estimate and the share of new detail it gives: a row's local
//! mean squared difference from the frame before, the noise's level per band
//! of brightness learnt from it, and the share of a new frame's detail taken
//! at its ratio to that level: little where only noise differs, all of it
//! where the face moved.

use super::channel::NO_DETAIL;
use super::rows::box_row;
use super::walk::{ChannelRows, MOTION_SPAN, SMOOTH_ROWS, Scratch};
use super::{
    BANDS, LEVELS, MIN_NOISE, MOTION_RADIUS, MOVING_RATIO, NOISE_RISE, STILL_RATIO, STILL_SHARE,
};

impl ChannelRows<'_> {
    /// The motion of row `y` of the area, from the squared differences of
    /// the rows round it, into `s.motion`; and every `step`th sample of the
    /// area's that the frame before had detail at, into `seen` by band.
    #[inline(always)]
    pub(super) fn motion_row(
        &mut self,
        y: usize,
        (w, h): (usize, usize),
        step: usize,
        s: &mut Scratch,
    ) {
        let (lo, hi) = (
            y.saturating_sub(MOTION_RADIUS),
            (y + MOTION_RADIUS + 1).min(h),
        );
        let scale = 1.0 / (hi - lo) as f32;
        let (column, squared) = (&mut s.column, &s.squared);
        // Added from the top, as the blur of a whole map adds its rows.
        if hi - lo == MOTION_SPAN {
            let rows: [&[f32]; MOTION_SPAN] =
                std::array::from_fn(|r| &squared[(lo + r) % MOTION_SPAN][..]);
            for (x, c) in column.iter_mut().enumerate() {
                let mut sum = rows[0][x];
                for row in &rows[1..] {
                    sum += row[x];
                }
                *c = sum * scale;
            }
        } else {
            column.copy_from_slice(&squared[lo % MOTION_SPAN]);
            for r in lo + 1..hi {
                (column.iter_mut().zip(&squared[r % MOTION_SPAN])).for_each(|(c, v)| *c += v);
            }
            column.iter_mut().for_each(|c| *c *= scale);
        }
        box_row::<MOTION_SPAN>(&s.column, &mut s.motion);
        let smooth = &s.smooth[y % SMOOTH_ROWS];
        // The samples are chosen by their index in the whole area, so that
        // the halves see together what one walk over it would.
        let row = y * w..(y + 1) * w;
        let offset = self.rows.start * w;
        let mut i = row.start.div_ceil(step) * step;
        while i < row.end {
            if self.detail[i - offset] != NO_DETAIL {
                let x = i - row.start;
                self.seen[band(smooth[x])].push(s.motion[x]);
            }
            i += step;
        }
    }
}

/// Updates `noise`, the noise's level per band of the smooth value, from the
/// local mean squared differences `seen` in each band of one frame.
pub(super) fn learn_noise(noise: &mut [Option<f32>; BANDS], seen: &mut [Vec<f32>; BANDS]) {
    for (noise, seen) in noise.iter_mut().zip(seen.iter_mut()) {
        if seen.len() < 32 {
            continue;
        }
        // A low quantile: in most frames a fifth of what is round a face
        // holds still, whatever moves. The 20th percentile of the mean of 9
        // squared normal variables is 0.598 of their variance.
        let fifth = seen.len() / 5;
        let quantile = *seen.select_nth_unstable_by(fifth, f32::total_cmp).1;
        let estimate = (quantile / 0.598).max(MIN_NOISE);
        *noise = Some(match *noise {
            Some(n) => estimate.min(n * (1.0 + NOISE_RISE)),
            None => estimate,
        });
    }
}

/// The noise's level for each band, a band with no estimate of its own
/// taking the nearest band's; None when no band is known.
pub(super) fn per_band(noise: &[Option<f32>; BANDS]) -> Option<[f32; BANDS]> {
    let known: Vec<(usize, f32)> = (noise.iter().enumerate())
        .filter_map(|(b, n)| n.map(|n| (b, n)))
        .collect();
    if known.is_empty() {
        return None;
    }
    Some(std::array::from_fn(|b| {
        known
            .iter()
            .min_by_key(|(k, _)| k.abs_diff(b))
            .map(|&(_, n)| n)
            .expect("at least one band is known")
    }))
}

/// The filtered detail of a sample of detail `d` whose filtered detail was
/// `past` (`restored`), at a local mean squared difference `ratio` times the
/// noise's level.
#[inline(always)]
pub(super) fn filtered(past: f32, d: f32, ratio: f32) -> f32 {
    past + new_share(ratio) * (d - past)
}

/// The band of [`LEVELS`] a smooth value lies in.
pub(super) fn band(smooth: f32) -> usize {
    (smooth.max(0.0) as usize / LEVELS).min(BANDS - 1)
}

/// Each of a row's local mean squared differences `motion` over the noise's
/// level at its smooth value, `inverse` being 1 over the noise per band.
#[inline(always)]
pub(super) fn over_noise(motion: &mut [f32], smooth: &[f32], inverse: &[f32; BANDS]) {
    // Chosen at run time in every build of the walk, the portable one too.
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { over_noise_avx2(motion, smooth, inverse) };
    }
    over_noise_plain(motion, smooth, inverse);
}

/// `over_noise` a sample at a time.
#[inline(always)]
pub(super) fn over_noise_plain(motion: &mut [f32], smooth: &[f32], inverse: &[f32; BANDS]) {
    for (m, &s) in motion.iter_mut().zip(smooth) {
        *m *= inverse[band(s)];
    }
}

/// `over_noise` with AVX2: the band's value is picked by a permutation of a
/// vector that holds one band a lane, where the compiler, from an index,
/// picks one sample at a time. The same band and product: the smooth value
/// times 1/[`LEVELS`] (a power of two, so exact) truncated is `band`'s.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) fn over_noise_avx2(motion: &mut [f32], smooth: &[f32], inverse: &[f32; BANDS]) {
    use std::arch::x86_64::*;
    const LANES: usize = 8;
    const { assert!(BANDS == LANES && LEVELS.is_power_of_two()) };
    let n = motion.len().min(smooth.len());
    let (motion, smooth) = (&mut motion[..n], &smooth[..n]);
    let last_band = _mm256_set1_epi32(BANDS as i32 - 1);
    let per_level = _mm256_set1_ps(1.0 / LEVELS as f32);
    // SAFETY: each load and store reads or writes 8 floats of a slice of 8
    // (`inverse`, or a chunk of 8).
    unsafe {
        let table = _mm256_loadu_ps(inverse.as_ptr());
        for (m, s) in (motion.chunks_exact_mut(LANES)).zip(smooth.chunks_exact(LANES)) {
            let s = _mm256_max_ps(_mm256_loadu_ps(s.as_ptr()), _mm256_setzero_ps());
            let b = _mm256_min_epi32(_mm256_cvttps_epi32(_mm256_mul_ps(s, per_level)), last_band);
            let over = _mm256_mul_ps(
                _mm256_loadu_ps(m.as_ptr()),
                _mm256_permutevar8x32_ps(table, b),
            );
            _mm256_storeu_ps(m.as_mut_ptr(), over);
        }
    }
    let done = n - n % LANES;
    over_noise_plain(&mut motion[done..], &smooth[done..], inverse);
}

/// Share of the new frame's detail at a local mean squared difference of
/// `ratio` times the noise's: [`STILL_SHARE`] up to [`STILL_RATIO`], all of
/// it from [`MOVING_RATIO`], by smoothstep between.
#[inline(always)]
pub(super) fn new_share(ratio: f32) -> f32 {
    let t = ((ratio - STILL_RATIO) / (MOVING_RATIO - STILL_RATIO)).clamp(0.0, 1.0);
    STILL_SHARE + (1.0 - STILL_SHARE) * t * t * (3.0 - 2.0 * t)
}
