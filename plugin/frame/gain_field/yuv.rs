//! The field's change on Y'CbCr frames: what the per-channel RGB gains make
//! of each pixel's own Y, Cb and Cr, without converting the frame.
//!
//! Y'CbCr is an affine function of RGB, so a per-channel gain on RGB is an
//! affine map of Y, Cb and Cr whose coefficients depend on the gains alone:
//! for lifted RGB `c + ε` (the pivot of [`super::LIFT`]) taking gains
//! `g = (g_R, g_G, g_B)`, with `ḡ = Σ k_c g_c` the luma-weighted mean gain,
//!
//! - luma: `Y' + p = ḡ (Y + p) + a_R (g_R − g_G)(Cr − 128) + a_B (g_B − g_G)(Cb − 128)`,
//! - Cb: `Cb' − 128 = b_Y (g_B − ḡ)(Y + p) + (g_B − k_B (g_B − g_G))(Cb − 128)
//!   − b_R (g_R − g_G)(Cr − 128)`, and Cr likewise,
//!
//! `a` and `b` constants of the matrix ([`YuvChange`]'s `luma_from_cr`,
//! `luma_from_cb`, `cb_from_luma`, `cb_from_cr`).
//!
//! Each pixel's colour change is then the RGB path's, up to rounding: in
//! particular the change of colour scales with the pixel's own brightness, so
//! dark hair next to a bright cheek takes the same tint ratio, not the cheek's
//! offset. Where chroma is subsampled, a chroma sample takes the mean luma of
//! the pixels it covers, and each of those pixels its chroma sample's colour
//! term; luma keeps its own smoothly interpolated `ḡ`.
//!
//! Luma is dithered as packed RGB is; chroma is only rounded. A step of one
//! level of chroma shows far less than one of luma, and on 4:2:0 chroma the
//! 4 × 4 pattern would cover 8 × 8 pixels, a coarse grain in the colour of
//! the skin (on the astronaut portrait in I420, `examples/real_footage`,
//! mottling 2.81% dithered against 2.03% rounded).

use std::ops::Range;

use super::{
    DITHER, FieldRow, FieldRows, GainField, LIFT, dither_rows, dither_runs, gain_row, pixel_xs,
};
use crate::frame::{FrameMut, YuvMatrix, round_to_u8};

/// The coefficients of the affine map a set of RGB gains makes of Y, Cb and
/// Cr bytes, for one Y'CbCr matrix (see the module's documentation).
#[derive(Clone, Copy, Debug)]
pub(in crate::frame) struct YuvChange {
    /// Luma weights of R, G and B.
    k: [f32; 3],
    /// `p`: the luma byte plus `p` is proportional to lifted luma.
    pivot: f32,
    luma_from_cr: f32,
    luma_from_cb: f32,
    cb_from_luma: f32,
    cr_from_luma: f32,
    cb_from_cr: f32,
    cr_from_cb: f32,
}

impl YuvChange {
    pub(in crate::frame) fn new(matrix: YuvMatrix) -> YuvChange {
        let (kr, kb) = (matrix.kr, matrix.kb);
        let (luma_offset, luma_scale, chroma_scale) = matrix.scales();
        YuvChange {
            k: [kr, 1.0 - kr - kb, kb],
            pivot: luma_scale * LIFT / 255.0 - luma_offset,
            luma_from_cr: luma_scale * 2.0 * kr * (1.0 - kr) / chroma_scale,
            luma_from_cb: luma_scale * 2.0 * kb * (1.0 - kb) / chroma_scale,
            cb_from_luma: chroma_scale / (2.0 * (1.0 - kb) * luma_scale),
            cr_from_luma: chroma_scale / (2.0 * (1.0 - kr) * luma_scale),
            cb_from_cr: kr * (1.0 - kr) / (1.0 - kb),
            cr_from_cb: kb * (1.0 - kb) / (1.0 - kr),
        }
    }

    /// `ḡ`: the gain of luma on a pixel without colour.
    pub(super) fn luma_gain(&self, g: [f32; 3]) -> f32 {
        self.k[0] * g[0] + self.k[1] * g[1] + self.k[2] * g[2]
    }

    /// For a chroma sample whose pixels take RGB gains `g`, of mean luma
    /// `luma`, with Cb and Cr `cb` and `cr` (bytes, as f32): what its pixels'
    /// luma takes besides `ḡ (Y + p) − p`, and its new Cb and Cr (neither
    /// rounded nor clamped).
    #[inline(always)]
    pub(super) fn chroma(&self, g: [f32; 3], luma: f32, cb: f32, cr: f32) -> [f32; 3] {
        let (u, v) = (cb - 128.0, cr - 128.0);
        let mean = self.luma_gain(g);
        let (red, blue) = (g[0] - g[1], g[2] - g[1]);
        let lifted = luma + self.pivot;
        [
            self.luma_from_cr * red * v + self.luma_from_cb * blue * u,
            128.0 + self.cb_from_luma * (g[2] - mean) * lifted + (g[2] - self.k[2] * blue) * u
                - self.cb_from_cr * red * v,
            128.0 + self.cr_from_luma * (g[0] - mean) * lifted + (g[0] - self.k[0] * red) * v
                - self.cr_from_cb * blue * u,
        ]
    }
}

impl FieldRow {
    /// Lanes `samples` of each of the three planes, `count` lanes each, the
    /// row holds.
    fn planes(&self, count: usize, samples: &Range<usize>) -> [&[f32]; 3] {
        let plane = |c: usize| &self.gain[c * count..(c + 1) * count][samples.clone()];
        [plane(0), plane(1), plane(2)]
    }
}

/// Mean of `count` luma bytes summing to `sum`: what a chroma sample's Cb and
/// Cr change by. A chroma sample covers 1, 2 or 4 pixels, whose reciprocals
/// are exact, so the product is the quotient, without a division per sample.
#[inline(always)]
fn block_mean(sum: u16, count: usize) -> f32 {
    debug_assert!(matches!(count, 1 | 2 | 4), "{count} pixels a chroma sample");
    f32::from(sum) * (1.0 / count as f32)
}

/// Adds each block of `SUB` bytes of a luma row (the last one may be short)
/// to its chroma sample's sum.
#[inline(always)]
fn add_blocks<const SUB: usize>(sums: &mut [u16], row: &[u8]) {
    let whole = row.len() / SUB;
    // Equal lengths up front let the compiler drop the bounds checks and
    // vectorise.
    let (sums, rest) = sums.split_at_mut(whole);
    let (blocks, tail) = row.split_at(whole * SUB);
    for k in 0..whole {
        for b in 0..SUB {
            sums[k] += u16::from(blocks[SUB * k + b]);
        }
    }
    if let Some(last) = rest.first_mut() {
        *last += tail.iter().map(|&v| u16::from(v)).sum::<u16>();
    }
}

/// Byte `byte` of each `STEP` bytes of `row`, as f32.
#[inline(always)]
fn read_lane<const STEP: usize>(out: &mut [f32], row: &[u8], byte: usize) {
    for (o, sample) in out.iter_mut().zip(row.chunks_exact(STEP)) {
        *o = f32::from(sample[byte]);
    }
}

/// `values`, rounded, into byte `byte` of each `STEP` bytes of `row`.
#[inline(always)]
pub(in crate::frame) fn write_lane<const STEP: usize>(row: &mut [u8], byte: usize, values: &[f32]) {
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if STEP == 1 && std::arch::is_x86_feature_detected!("avx2") {
        debug_assert_eq!(byte, 0, "a plane of one byte a sample");
        // SAFETY: the CPU has AVX2, checked just above.
        done = unsafe { write_bytes_avx2(row, values) };
    }
    for (sample, &v) in row[done * STEP..]
        .chunks_exact_mut(STEP)
        .zip(&values[done..])
    {
        sample[byte] = round_to_u8(v);
    }
}

/// `write_lane::<1>` 32 samples at a time, as many as fill whole blocks:
/// a plane of its own (I420's Cb and Cr) takes whole vectors, where the
/// compiler stored each byte on its own. Returns the samples written.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn write_bytes_avx2(row: &mut [u8], values: &[f32]) -> usize {
    use super::avx2::{BLOCK, LANES, round_to_u8, store_bytes};
    use std::arch::x86_64::*;
    let n = row.len().min(values.len());
    let whole = n - n % BLOCK;
    for k in (0..whole).step_by(BLOCK) {
        let mut rounded = [_mm256_setzero_si256(); BLOCK / LANES];
        for (j, out) in rounded.iter_mut().enumerate() {
            // SAFETY: k + j * LANES + LANES <= whole <= values.len().
            let v = unsafe { _mm256_loadu_ps(values.as_ptr().add(k + j * LANES)) };
            *out = round_to_u8(v);
        }
        store_bytes(&mut row[k..k + BLOCK], rounded);
    }
    whole
}

/// Per pixel of a luma row, its chroma sample's term (`extra`, one a block of
/// `SUB` pixels, the last block maybe short) plus its dither.
#[inline(always)]
pub(in crate::frame) fn spread<const SUB: usize>(out: &mut [f32], extra: &[f32], dither: &[f32]) {
    #[cfg(target_arch = "x86_64")]
    if SUB == 2 && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { spread_pairs_avx2(out, extra, dither) };
    }
    spread_portable::<SUB>(out, extra, dither)
}

/// `spread::<2>` 16 pixels at a time: each of 8 terms doubled in the
/// vectors, where the compiler's build shuffled element by element.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn spread_pairs_avx2(out: &mut [f32], extra: &[f32], dither: &[f32]) {
    use std::arch::x86_64::*;
    const PIXELS: usize = 16;
    let len = out.len();
    let whole = (len / PIXELS).min(extra.len() / (PIXELS / 2)) * PIXELS;
    let dither = &dither[..len];
    for k in (0..whole).step_by(PIXELS) {
        // SAFETY: k + PIXELS <= whole <= len, the length of `out` and
        // `dither`, and k / 2 + 8 <= extra.len().
        unsafe {
            let terms = _mm256_loadu_ps(extra.as_ptr().add(k / 2));
            // (e0 e0 e1 e1 | e4 e4 e5 e5) and (e2 e2 e3 e3 | e6 e6 e7 e7).
            let (low, high) = (
                _mm256_unpacklo_ps(terms, terms),
                _mm256_unpackhi_ps(terms, terms),
            );
            let pairs = [
                _mm256_permute2f128_ps::<0x20>(low, high),
                _mm256_permute2f128_ps::<0x31>(low, high),
            ];
            for (half, pair) in pairs.into_iter().enumerate() {
                let at = k + half * PIXELS / 2;
                let sum = _mm256_add_ps(pair, _mm256_loadu_ps(dither.as_ptr().add(at)));
                _mm256_storeu_ps(out.as_mut_ptr().add(at), sum);
            }
        }
    }
    spread_portable::<2>(&mut out[whole..], &extra[whole / 2..], &dither[whole..]);
}

// Always inlined, so that the paste's AVX2 build holds a copy built for AVX2.
#[inline(always)]
pub(in crate::frame) fn spread_portable<const SUB: usize>(
    out: &mut [f32],
    extra: &[f32],
    dither: &[f32],
) {
    let (whole, len) = (out.len() / SUB, out.len());
    let (blocks, tail) = out.split_at_mut(whole * SUB);
    let (dither, tail_dither) = dither[..len].split_at(whole * SUB);
    let extra = &extra[..whole + usize::from(!tail.is_empty())];
    for k in 0..whole {
        for b in 0..SUB {
            blocks[SUB * k + b] = extra[k] + dither[SUB * k + b];
        }
    }
    for (o, &d) in tail.iter_mut().zip(tail_dither) {
        *o = extra[whole] + d;
    }
}

/// [`spread`] over pixels `run` of a luma row (`out`, from the row's first
/// changed pixel; `extra` per chroma sample from the same place), each with
/// its dither (`dither`, the run's). A run may start inside a chroma sample.
#[inline(always)]
fn spread_run<const SUB: usize>(out: &mut [f32], extra: &[f32], run: Range<usize>, dither: &[f32]) {
    let (mut from, mut dither) = (run.start, dither);
    if from % SUB != 0 {
        out[from] = extra[from / SUB] + dither[0];
        (from, dither) = (from + 1, &dither[1..]);
    }
    spread::<SUB>(&mut out[from..run.end], &extra[from / SUB..], dither);
}

impl GainField {
    /// Applies the field to a YUV frame. Per chroma row: the gains at its
    /// samples, their pixels' mean luma and their Cb and Cr, read before any
    /// of them change; the new Cb and Cr; then its luma rows, each pixel with
    /// its own `ḡ` and its chroma sample's colour term.
    ///
    /// Only frame rows `rows` (`rows.start` even), where `frame`'s planes start.
    pub(super) fn paste_yuv(
        &self,
        yuv: &YuvChange,
        luma_gain: &[f32],
        frame: &mut FrameMut,
        rows: Range<usize>,
    ) {
        // AVX2, where the CPU has it, doubles the vectors' width of the loops
        // over a row, with the same results (see `gain_row`).
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.paste_yuv_avx2(yuv, luma_gain, frame, rows) };
        }
        self.paste_yuv_portable(yuv, luma_gain, frame, rows)
    }

    /// `paste_yuv_portable` built for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn paste_yuv_avx2(
        &self,
        yuv: &YuvChange,
        luma_gain: &[f32],
        frame: &mut FrameMut,
        rows: Range<usize>,
    ) {
        self.paste_yuv_portable(yuv, luma_gain, frame, rows)
    }

    // Always inlined, so that `paste_yuv_avx2` holds a copy built for AVX2.
    #[inline(always)]
    fn paste_yuv_portable(
        &self,
        yuv: &YuvChange,
        luma_gain: &[f32],
        frame: &mut FrameMut,
        rows: Range<usize>,
    ) {
        let (width, height) = (frame.width, frame.height);
        let [
            (cb_plane, sub, cb_step, cb_byte),
            (cr_plane, _, cr_step, cr_byte),
        ] = frame.format.chroma_lanes();
        let (chroma_width, chroma_height) = (width.div_ceil(sub), height.div_ceil(sub));
        let (luma_x, luma_y) = (self.taps(width, 1, 0), self.taps(height, 1, 1));
        let (chroma_x, chroma_y) = (
            self.taps(chroma_width, sub, 0),
            self.taps(chroma_height, sub, 1),
        );
        let luma_rows = |cy: usize| sub * cy..(sub * cy + sub).min(height);
        let chroma_rows = rows.start / sub..rows.end.div_ceil(sub).min(chroma_height);
        // Planes' rows from the first of `rows`.
        let (luma_row, chroma_row) = (|y: usize| y - rows.start, |cy| cy - chroma_rows.start);
        // Per chroma row, the chroma columns it or its luma rows change.
        let spans: Vec<Option<(usize, usize)>> = chroma_rows
            .clone()
            .map(|cy| {
                let luma = luma_rows(cy)
                    .filter_map(|y| self.changed_columns(&luma_x, luma_y[y].0))
                    .map(|(a, b)| (a / sub, b.div_ceil(sub)));
                self.changed_columns(&chroma_x, chroma_y[cy].0)
                    .into_iter()
                    .chain(luma)
                    .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
            })
            .collect();
        let Some((first, end)) = spans
            .iter()
            .flatten()
            .copied()
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
        else {
            return;
        };
        let count = end - first;
        let (luma_first, luma_end) = (first * sub, (end * sub).min(width));
        let (chroma_x, luma_x) = (&chroma_x[first..end], &luma_x[luma_first..luma_end]);
        let mut gain_rows = FieldRows::new(3 * count);
        let mut luma_gain_rows = FieldRows::new(luma_x.len());
        let luma_dither = dither_rows(luma_first, luma_x.len(), 1);
        let (xs, zeros) = (
            pixel_xs(luma_first, luma_x.len(), 1),
            vec![0f32; luma_x.len()],
        );
        // Per chroma sample of the row: mean luma, Cb and Cr in, the luma
        // term, Cb and Cr out.
        let (mut sums, mut luma) = (vec![0u16; count], vec![0f32; count]);
        let (mut cb, mut cr, mut extra) = (vec![0f32; count], vec![0f32; count], vec![0f32; count]);
        // Per pixel of a luma row: its chroma sample's term, dithered.
        let mut luma_extra = vec![0f32; luma_x.len()];
        for (cy, span) in chroma_rows.clone().zip(&spans) {
            let Some((a, b)) = *span else {
                continue;
            };
            let samples = a - first..b - first;
            let pixels = (a * sub).min(width) - luma_first..(b * sub).min(width) - luma_first;
            // Luma, before it changes.
            let (data, stride) = (&*frame.planes[0].0, frame.planes[0].1);
            let sums = &mut sums[samples.clone()];
            sums.fill(0);
            for y in luma_rows(cy) {
                let row = &data[luma_row(y) * stride + luma_first..][pixels.clone()];
                match sub {
                    1 => add_blocks::<1>(sums, row),
                    _ => add_blocks::<2>(sums, row),
                }
            }
            let rows = luma_rows(cy).len();
            for (m, &s) in luma[samples.clone()].iter_mut().zip(&*sums) {
                *m = block_mean(s, rows * sub);
            }
            if (a * sub..b * sub).contains(&width) {
                // The last sample of an odd width covers one column.
                luma[samples.end - 1] = block_mean(sums[sums.len() - 1], rows);
            }
            // Cb and Cr, before they change.
            for (out, (plane, step, byte)) in [
                (&mut cb, (cb_plane, cb_step, cb_byte)),
                (&mut cr, (cr_plane, cr_step, cr_byte)),
            ] {
                let (data, stride) = (&*frame.planes[plane].0, frame.planes[plane].1);
                let start = chroma_row(cy) * stride;
                let row = &data[start + a * step..start + b * step];
                let out = &mut out[samples.clone()];
                match step {
                    1 => read_lane::<1>(out, row, byte),
                    _ => read_lane::<2>(out, row, byte),
                }
            }
            let (ly, ty) = chroma_y[cy];
            let (top, bottom) = gain_rows.at(ly, |r, out| {
                for (c, out) in out.gain.chunks_exact_mut(count).enumerate() {
                    self.interpolate_map_row(&self.gain[c], r, chroma_x, out.iter_mut());
                }
            });
            chroma_change(
                yuv,
                ty,
                (top.planes(count, &samples), bottom.planes(count, &samples)),
                &luma[samples.clone()],
                (&mut cb[samples.clone()], &mut cr[samples.clone()]),
                &mut extra[samples.clone()],
            );
            for (values, (plane, step, byte)) in [
                (&cb, (cb_plane, cb_step, cb_byte)),
                (&cr, (cr_plane, cr_step, cr_byte)),
            ] {
                let (data, stride) = (&mut *frame.planes[plane].0, frame.planes[plane].1);
                let start = chroma_row(cy) * stride;
                let row = &mut data[start + a * step..start + b * step];
                let values = &values[samples.clone()];
                match step {
                    1 => write_lane::<1>(row, byte, values),
                    _ => write_lane::<2>(row, byte, values),
                }
            }
            // Luma rows, each pixel with its chroma sample's term.
            for y in luma_rows(cy) {
                // No dither where the disc holds the pixel.
                let hole = self.undithered.span(&xs, y as f32 + 0.5);
                let runs = dither_runs(pixels.clone(), hole, &luma_dither[y % DITHER], &zeros);
                for (run, dither) in runs {
                    match sub {
                        1 => spread_run::<1>(&mut luma_extra, &extra, run, dither),
                        _ => spread_run::<2>(&mut luma_extra, &extra, run, dither),
                    }
                }
                let (ly, ty) = luma_y[y];
                let (top, bottom) = luma_gain_rows.at(ly, |r, out| {
                    self.interpolate_map_row(luma_gain, r, luma_x, out.gain.iter_mut());
                });
                let (data, stride) = (&mut *frame.planes[0].0, frame.planes[0].1);
                let start = luma_row(y) * stride + luma_first;
                gain_row(
                    &mut data[start + pixels.start..start + pixels.end],
                    ty,
                    (&top.gain[pixels.clone()], &bottom.gain[pixels.clone()]),
                    yuv.pivot,
                    &luma_extra[pixels.clone()],
                );
            }
        }
    }

    /// The luma term and the new Cb and Cr (before rounding) at
    /// chroma sample (`cx`, `cy`) with taps `x` and `y`, whose pixels' luma
    /// bytes sum to `luma_sum` over `count` of them: the field sampled on its
    /// own, for the reference paste.
    #[cfg(test)]
    pub(in crate::frame) fn chroma_at(
        &self,
        x: (usize, f32),
        y: (usize, f32),
        (luma_sum, count): (u16, usize),
        (cb, cr): (u8, u8),
    ) -> [f32; 3] {
        let (yuv, _) = self.yuv.as_ref().expect("a YUV field");
        let g = [0, 1, 2].map(|c| self.sample(&self.gain[c], x, y));
        yuv.chroma(g, block_mean(luma_sum, count), cb.into(), cr.into())
    }

    /// Luma byte `v` at a pixel with taps `x` and `y`, relit, with `extra`
    /// (its chroma sample's term and the dither) added: for the reference paste.
    #[cfg(test)]
    pub(in crate::frame) fn luma_at(
        &self,
        v: u8,
        x: (usize, f32),
        y: (usize, f32),
        extra: f32,
    ) -> f32 {
        let (yuv, luma_gain) = self.yuv.as_ref().expect("a YUV field");
        let gain = self.sample(luma_gain, x, y);
        gain * (v as f32 + yuv.pivot) - yuv.pivot + extra
    }
}

/// Per chroma sample of a row: the gains interpolated between the grid rows
/// `top` and `bottom` (planar R, G, B) at `ty`, and from them, its mean luma
/// and its Cb and Cr, the luma term (into `extra`) and the new Cb and Cr
/// (into `cb` and `cr`).
pub(in crate::frame) fn chroma_change(
    yuv: &YuvChange,
    ty: f32,
    rows: ([&[f32]; 3], [&[f32]; 3]),
    luma: &[f32],
    chroma: (&mut [f32], &mut [f32]),
    extra: &mut [f32],
) {
    // AVX2 doubles the vectors' width, with the same results (see `gain_row`).
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { chroma_change_avx2(yuv, ty, rows, luma, chroma, extra) };
    }
    chroma_change_portable(yuv, ty, rows, luma, chroma, extra)
}

/// `chroma_change_portable` built for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn chroma_change_avx2(
    yuv: &YuvChange,
    ty: f32,
    rows: ([&[f32]; 3], [&[f32]; 3]),
    luma: &[f32],
    chroma: (&mut [f32], &mut [f32]),
    extra: &mut [f32],
) {
    chroma_change_portable(yuv, ty, rows, luma, chroma, extra)
}

// Always inlined, so that `chroma_change_avx2` holds a copy built for AVX2.
#[inline(always)]
pub(in crate::frame) fn chroma_change_portable(
    yuv: &YuvChange,
    ty: f32,
    (top, bottom): ([&[f32]; 3], [&[f32]; 3]),
    luma: &[f32],
    (cb, cr): (&mut [f32], &mut [f32]),
    extra: &mut [f32],
) {
    let uy = 1.0 - ty;
    // Equal lengths up front let the compiler drop the bounds checks.
    let n = luma.len();
    let [top, bottom] = [top, bottom].map(|[r, g, b]| [&r[..n], &g[..n], &b[..n]]);
    let (cb, cr, extra) = (&mut cb[..n], &mut cr[..n], &mut extra[..n]);
    for k in 0..n {
        let g = [
            top[0][k] * uy + bottom[0][k] * ty,
            top[1][k] * uy + bottom[1][k] * ty,
            top[2][k] * uy + bottom[2][k] * ty,
        ];
        let [t, new_cb, new_cr] = yuv.chroma(g, luma[k], cb[k], cr[k]);
        extra[k] = t;
        cb[k] = new_cb;
        cr[k] = new_cr;
    }
}
