//! The per-row steps the walk is made of: one channel's bytes out of a row of
//! samples and its results back in, and the box blurs along a row.

use super::super::round_to_u8;
use super::SPLIT_RADIUS;
use super::walk::SPLIT_SPAN;

/// Byte `lane` of each of the first `out.len()` samples of `bytes` bytes of
/// `pixels`, into `out`.
#[inline(always)]
pub(super) fn lane_bytes(pixels: &[u8], bytes: usize, lane: usize, out: &mut [u8]) {
    // With the sample's size known to the compiler, the loop picks bytes out
    // of whole vectors of pixels rather than one at a time.
    match bytes {
        1 => out.copy_from_slice(&pixels[..out.len()]),
        2 => lane_of::<2>(pixels, lane, out),
        3 => lane_of::<3>(pixels, lane, out),
        4 => lane_of::<4>(pixels, lane, out),
        bytes => {
            let samples = pixels[lane..].iter().step_by(bytes);
            out.iter_mut().zip(samples).for_each(|(v, &b)| *v = b);
        }
    }
}

/// Byte `lane` of each of the first `out.len()` samples of `BYTES` bytes
/// of `pixels`, into `out`.
#[inline(always)]
fn lane_of<const BYTES: usize>(pixels: &[u8], lane: usize, out: &mut [u8]) {
    // Samples of 2 and 4 bytes are read as whole words and the lane shifted
    // down: a shift and a narrowing a vector. Picked by index, the compiler
    // sometimes gathered the bytes one at a time (one `vpinsrb` each), which
    // made BGRx's denoising 10% slower or not by the build's luck.
    let shift = 8 * lane;
    match BYTES {
        2 => {
            for (v, p) in out.iter_mut().zip(pixels.chunks_exact(2)) {
                *v = (u16::from_le_bytes([p[0], p[1]]) >> shift) as u8;
            }
        }
        4 => {
            for (v, p) in out.iter_mut().zip(pixels.chunks_exact(4)) {
                *v = (u32::from_le_bytes([p[0], p[1], p[2], p[3]]) >> shift) as u8;
            }
        }
        _ => {
            for (v, pixel) in out.iter_mut().zip(pixels.chunks_exact(BYTES)) {
                *v = pixel[lane];
            }
        }
    }
}

/// Byte `lane` of each of the first `values.len()` samples of `BYTES` bytes
/// of `pixels`: the value rounded.
#[inline(always)]
pub(super) fn set_lane<const BYTES: usize>(pixels: &mut [u8], lane: usize, values: &[f32]) {
    // As `lane_of`: samples of 2 and 4 bytes are rewritten as whole words,
    // the lane masked in, so the loop stores vectors, not a byte at a time.
    let shift = 8 * lane;
    match BYTES {
        2 => {
            let keep = !(0xffu16 << shift);
            for (pixel, &r) in pixels.chunks_exact_mut(2).zip(values) {
                let word = u16::from_le_bytes([pixel[0], pixel[1]]);
                let word = word & keep | u16::from(round_to_u8(r)) << shift;
                pixel.copy_from_slice(&word.to_le_bytes());
            }
        }
        4 => {
            let keep = !(0xffu32 << shift);
            for (pixel, &r) in pixels.chunks_exact_mut(4).zip(values) {
                let word = u32::from_le_bytes([pixel[0], pixel[1], pixel[2], pixel[3]]);
                let word = word & keep | u32::from(round_to_u8(r)) << shift;
                pixel.copy_from_slice(&word.to_le_bytes());
            }
        }
        _ => {
            for (pixel, &r) in pixels.chunks_exact_mut(BYTES).zip(values) {
                pixel[lane] = round_to_u8(r);
            }
        }
    }
}

/// The smooth values of row `y` of a `w` × `h` map, whose rows round it
/// `ring` holds by row modulo [`SPLIT_SPAN`]: the mean of the samples within
/// [`SPLIT_RADIUS`] each way, the window shrinking at the borders, into
/// `out`; `sums` holds the vertical sums. The sums are of whole numbers,
/// exact in any order, and scaled once.
#[inline(always)]
pub(super) fn smooth_row(
    ring: &[u8],
    (w, h): (usize, usize),
    y: usize,
    sums: &mut [u16],
    out: &mut [f32],
) {
    let (lo, hi) = (
        y.saturating_sub(SPLIT_RADIUS),
        (y + SPLIT_RADIUS + 1).min(h),
    );
    let rows = hi - lo;
    let row = |r: usize| &ring[(r % SPLIT_SPAN) * w..][..w];
    if rows == SPLIT_SPAN {
        let rows: [&[u8]; SPLIT_SPAN] = std::array::from_fn(row);
        for (x, s) in sums.iter_mut().enumerate() {
            let mut sum = rows[0][x] as u16;
            for row in &rows[1..] {
                sum += row[x] as u16;
            }
            *s = sum;
        }
    } else {
        sums.iter_mut()
            .zip(row(lo))
            .for_each(|(s, &b)| *s = b as u16);
        for r in lo + 1..hi {
            sums.iter_mut()
                .zip(row(r))
                .for_each(|(s, &b)| *s += b as u16);
        }
    }
    let mean = |sum: u16, columns: usize| sum as f32 * (1.0 / (rows * columns) as f32);
    if w >= SPLIT_SPAN {
        // Samples with the whole window: out[k] sums sums[k - radius..=k + radius].
        let m = w + 1 - SPLIT_SPAN;
        let shifted: [&[u16]; SPLIT_SPAN] = std::array::from_fn(|s| &sums[s..s + m]);
        for (k, o) in out[SPLIT_RADIUS..SPLIT_RADIUS + m].iter_mut().enumerate() {
            let mut sum = shifted[0][k];
            for run in &shifted[1..] {
                sum += run[k];
            }
            *o = mean(sum, SPLIT_SPAN);
        }
    }
    // The ends' shrunken windows (every sample, in a row narrower than one).
    for k in (0..SPLIT_RADIUS.min(w)).chain(SPLIT_RADIUS.max(w.saturating_sub(SPLIT_RADIUS))..w) {
        let (first, end) = (
            k.saturating_sub(SPLIT_RADIUS),
            (k + SPLIT_RADIUS + 1).min(w),
        );
        out[k] = mean(sums[first..end].iter().sum(), end - first);
    }
}

/// A row's horizontal box blur of `SPAN` samples, shrinking at the ends:
/// the window's samples added from the left, then scaled.
#[inline(always)]
pub(super) fn box_row<const SPAN: usize>(src: &[f32], dst: &mut [f32]) {
    let radius = SPAN / 2;
    let w = src.len();
    if w >= SPAN {
        // Samples with the whole window: dst[k] sums src[k - radius..=k + radius].
        let m = w + 1 - SPAN;
        let inner = &mut dst[radius..radius + m];
        let shifted: [&[f32]; SPAN] = std::array::from_fn(|s| &src[s..s + m]);
        let scale = 1.0 / SPAN as f32;
        for (k, o) in inner.iter_mut().enumerate() {
            let mut sum = shifted[0][k];
            for run in &shifted[1..] {
                sum += run[k];
            }
            *o = sum * scale;
        }
    }
    // The ends' shrunken windows (every sample, in a row narrower than one).
    for k in (0..radius.min(w)).chain(radius.max(w.saturating_sub(radius))..w) {
        let (lo, hi) = (k.saturating_sub(radius), (k + radius + 1).min(w));
        dst[k] = src[lo..hi].iter().sum::<f32>() / (hi - lo) as f32;
    }
}
