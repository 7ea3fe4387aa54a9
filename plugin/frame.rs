//! Raw video frames without GStreamer: formats, plane views, colour matrices,
//! the face crop, and putting a lighting change back into a frame.
//!
//! The network sees a square crop resampled to its resolution. Its output goes
//! back as a lighting change, not as an upscaled image: with `R` the relit
//! crop and `I` the network's input (both at network resolution) and `↑` a
//! bilinear upsampling to the frame,
//!
//! `out = R↑ + g↑ · (in − I↑)`,   `g = (lum(R) + ε) / (lum(I) + ε)`
//!
//! so the frame keeps its own detail, scaled by the local change in
//! brightness, and takes its low frequencies from the network. YUV is an
//! affine function of RGB, so the same equation runs on Y, U and V planes
//! directly and a YUV frame is never converted as a whole.

/// Pixel layouts the element handles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PixelFormat {
    I420,
    Nv12,
    Y444,
    Rgba,
    Bgra,
    Rgbx,
    Bgrx,
    Rgb,
    Bgr,
}

/// One plane's part in the crop and the paste, which walk each plane once.
#[derive(Clone, Copy, Debug)]
struct Pass {
    plane: usize,
    /// Frame pixels one of the plane's pixels covers in each direction.
    subsample: usize,
    /// Per byte of one of the plane's pixels, the channel it holds (0-2: R, G,
    /// B or Y, Cb, Cr), `None` for padding.
    lanes: &'static [Option<usize>],
}

impl Pass {
    const fn new(plane: usize, subsample: usize, lanes: &'static [Option<usize>]) -> Pass {
        Pass {
            plane,
            subsample,
            lanes,
        }
    }
}

impl PixelFormat {
    /// The layout of every format, in the order the planes are walked.
    fn passes(self) -> &'static [Pass] {
        const Y: Pass = Pass::new(0, 1, &[Some(0)]);
        const I420: &[Pass] = &[Y, Pass::new(1, 2, &[Some(1)]), Pass::new(2, 2, &[Some(2)])];
        const NV12: &[Pass] = &[Y, Pass::new(1, 2, &[Some(1), Some(2)])];
        const Y444: &[Pass] = &[Y, Pass::new(1, 1, &[Some(1)]), Pass::new(2, 1, &[Some(2)])];
        const RGBX: &[Pass] = &[Pass::new(0, 1, &[Some(0), Some(1), Some(2), None])];
        const BGRX: &[Pass] = &[Pass::new(0, 1, &[Some(2), Some(1), Some(0), None])];
        const RGB: &[Pass] = &[Pass::new(0, 1, &[Some(0), Some(1), Some(2)])];
        const BGR: &[Pass] = &[Pass::new(0, 1, &[Some(2), Some(1), Some(0)])];
        match self {
            PixelFormat::I420 => I420,
            PixelFormat::Nv12 => NV12,
            PixelFormat::Y444 => Y444,
            PixelFormat::Rgba | PixelFormat::Rgbx => RGBX,
            PixelFormat::Bgra | PixelFormat::Bgrx => BGRX,
            PixelFormat::Rgb => RGB,
            PixelFormat::Bgr => BGR,
        }
    }

    /// Byte offsets of R, G and B and bytes per pixel, for packed RGB formats.
    pub(crate) fn packed(self) -> Option<([usize; 3], usize)> {
        match self.passes() {
            [pass] => {
                let offset = |c| pass.lanes.iter().position(|&l| l == Some(c));
                Some((
                    [0, 1, 2].map(|c| offset(c).expect("R, G and B")),
                    pass.lanes.len(),
                ))
            }
            _ => None,
        }
    }

    /// Cb and Cr of frame pixel (x, y) of a YUV frame.
    pub(crate) fn chroma_at(self, planes: &[Plane; 3], x: usize, y: usize) -> (u8, u8) {
        assert!(self.is_yuv(), "{self:?} has no chroma");
        let mut cbcr = [0; 2];
        for pass in &self.passes()[1..] {
            let p = &planes[pass.plane];
            let (sub, bpp) = (pass.subsample, pass.lanes.len());
            let pixel = (y / sub) * p.stride + (x / sub) * bpp;
            for (b, lane) in pass.lanes.iter().enumerate() {
                if let Some(c) = *lane {
                    cbcr[c - 1] = p.data[pixel + b];
                }
            }
        }
        (cbcr[0], cbcr[1])
    }

    /// Where [`PixelFormat::chroma_at`] reads Cb and Cr: per channel its plane,
    /// the subsampling, the bytes a plane pixel and the byte within it; for code
    /// that reads many pixels and works out their offsets once.
    pub(crate) fn chroma_lanes(self) -> [(usize, usize, usize, usize); 2] {
        assert!(self.is_yuv(), "{self:?} has no chroma");
        let mut lanes = [(0, 1, 1, 0); 2];
        for pass in &self.passes()[1..] {
            for (b, lane) in pass.lanes.iter().enumerate() {
                if let Some(c) = *lane {
                    lanes[c - 1] = (pass.plane, pass.subsample, pass.lanes.len(), b);
                }
            }
        }
        lanes
    }

    pub fn is_yuv(self) -> bool {
        self.packed().is_none()
    }
}

/// The Y'CbCr matrix and range of a YUV stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YuvMatrix {
    pub kr: f32,
    pub kb: f32,
    /// Limited ("TV") range: Y in [16, 235], chroma in [16, 240].
    pub limited: bool,
}

impl YuvMatrix {
    pub const BT601_LIMITED: YuvMatrix = YuvMatrix {
        kr: 0.299,
        kb: 0.114,
        limited: true,
    };
    pub const BT709_LIMITED: YuvMatrix = YuvMatrix {
        kr: 0.2126,
        kb: 0.0722,
        limited: true,
    };

    fn scales(&self) -> (f32, f32, f32) {
        // (luma offset, luma scale, chroma scale), in units of 1/255.
        if self.limited {
            (16.0, 219.0, 224.0)
        } else {
            (0.0, 255.0, 255.0)
        }
    }

    /// 8-bit Y, Cb, Cr (as f32) to RGB in [0, 1], not clamped.
    pub fn to_rgb(&self, y: f32, cb: f32, cr: f32) -> [f32; 3] {
        let (yo, ys, cs) = self.scales();
        let y = (y - yo) / ys;
        let cb = (cb - 128.0) / cs;
        let cr = (cr - 128.0) / cs;
        let kg = 1.0 - self.kr - self.kb;
        let r = y + 2.0 * (1.0 - self.kr) * cr;
        let b = y + 2.0 * (1.0 - self.kb) * cb;
        let g = (y - self.kr * r - self.kb * b) / kg;
        [r, g, b]
    }

    /// RGB in [0, 1] to 8-bit Y, Cb, Cr as f32 (not rounded or clamped).
    pub fn from_rgb(&self, rgb: [f32; 3]) -> [f32; 3] {
        let (yo, ys, cs) = self.scales();
        let y = self.kr * rgb[0] + (1.0 - self.kr - self.kb) * rgb[1] + self.kb * rgb[2];
        let cb = (rgb[2] - y) / (2.0 * (1.0 - self.kb));
        let cr = (rgb[0] - y) / (2.0 * (1.0 - self.kr));
        [yo + ys * y, 128.0 + cs * cb, 128.0 + cs * cr]
    }
}

/// One plane: its bytes and row stride.
#[derive(Clone, Copy, Debug)]
pub struct Plane<'a> {
    pub data: &'a [u8],
    pub stride: usize,
}

/// A read-only frame.
#[derive(Clone, Copy, Debug)]
pub struct Frame<'a> {
    pub format: PixelFormat,
    pub width: usize,
    pub height: usize,
    pub planes: [Plane<'a>; 3],
    /// Used for YUV formats only.
    pub matrix: YuvMatrix,
}

/// A frame that owns its planes, each row `padding` bytes longer than its
/// pixels: for code that makes frames without GStreamer (tests, benchmarks).
pub struct OwnedFrame {
    pub format: PixelFormat,
    pub width: usize,
    pub height: usize,
    /// Each plane's bytes and stride.
    pub planes: Vec<(Vec<u8>, usize)>,
    pub matrix: YuvMatrix,
}

impl OwnedFrame {
    /// A frame of `format` whose bytes, padding included, come from `fill` in order.
    pub fn new(
        format: PixelFormat,
        (width, height): (usize, usize),
        padding: usize,
        matrix: YuvMatrix,
        mut fill: impl FnMut() -> u8,
    ) -> OwnedFrame {
        let (cw, ch) = (width.div_ceil(2), height.div_ceil(2));
        let rows = match (format.packed(), format) {
            (Some((_, bpp)), _) => vec![(bpp * width, height)],
            (None, PixelFormat::I420) => vec![(width, height), (cw, ch), (cw, ch)],
            (None, PixelFormat::Nv12) => vec![(width, height), (2 * cw, ch)],
            (None, _) => vec![(width, height); 3],
        };
        let planes = rows
            .into_iter()
            .map(|(bytes, rows)| {
                let stride = bytes + padding;
                ((0..stride * rows).map(|_| fill()).collect(), stride)
            })
            .collect();
        OwnedFrame {
            format,
            width,
            height,
            planes,
            matrix,
        }
    }

    pub fn frame(&self) -> Frame<'_> {
        let plane = |i: usize| {
            let (data, stride) = &self.planes[i.min(self.planes.len() - 1)];
            Plane {
                data,
                stride: *stride,
            }
        };
        Frame {
            format: self.format,
            width: self.width,
            height: self.height,
            planes: [plane(0), plane(1), plane(2)],
            matrix: self.matrix,
        }
    }

    pub fn frame_mut(&mut self) -> FrameMut<'_> {
        let mut planes = self.planes.iter_mut().map(|(d, s)| (d.as_mut_slice(), *s));
        let first = planes.next().expect("every format has a plane");
        let second = planes.next().unwrap_or((&mut [], 0));
        let third = planes.next().unwrap_or((&mut [], 0));
        FrameMut {
            format: self.format,
            width: self.width,
            height: self.height,
            planes: [first, second, third],
            matrix: self.matrix,
        }
    }
}

impl<'a> Frame<'a> {
    /// A view of tightly packed 8-bit RGB pixels.
    pub fn packed_rgb(data: &'a [u8], width: usize, height: usize) -> Frame<'a> {
        let plane = Plane {
            data,
            stride: width * 3,
        };
        Frame {
            format: PixelFormat::Rgb,
            width,
            height,
            planes: [plane, plane, plane],
            matrix: YuvMatrix::BT601_LIMITED,
        }
    }
}

/// A frame being written.
pub struct FrameMut<'a> {
    pub format: PixelFormat,
    pub width: usize,
    pub height: usize,
    pub planes: [(&'a mut [u8], usize); 3],
    pub matrix: YuvMatrix,
}

/// The square the network sees, in pixels of the frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    pub x: usize,
    pub y: usize,
    pub size: usize,
}

impl Crop {
    /// Whether `other` is this square moved or resized by at most 2% of its side:
    /// a followed face's crop from frame to frame, close enough that a lighting
    /// change computed for one serves the other.
    pub fn near(&self, other: Crop) -> bool {
        let tolerance = (self.size / 50).max(1);
        self.x.abs_diff(other.x) <= tolerance
            && self.y.abs_diff(other.y) <= tolerance
            && self.size.abs_diff(other.size) <= tolerance
    }

    /// A square of `size_fraction` of the frame's shorter side centred at
    /// (`cx`, `cy`) in fractions of the frame, moved inside the frame and kept
    /// even so chroma planes align.
    pub fn centred(width: usize, height: usize, cx: f64, cy: f64, size_fraction: f64) -> Crop {
        let short = width.min(height);
        let size = ((short as f64 * size_fraction.clamp(0.05, 1.0)).round() as usize)
            .clamp(2.min(short), short)
            & !1;
        let place = |centre: f64, extent: usize| {
            let x = (centre * extent as f64 - size as f64 / 2.0)
                .round()
                .max(0.0) as usize;
            x.min(extent - size) & !1
        };
        Crop {
            x: place(cx, width),
            y: place(cy, height),
            size,
        }
    }

    /// The same square in the pixels of a plane subsampled by `subsample`.
    fn in_plane(self, subsample: usize) -> Crop {
        Crop {
            x: self.x / subsample,
            y: self.y / subsample,
            size: self.size / subsample,
        }
    }
}

/// Area weights of resampling `n_in` samples to `n_out`: per output sample,
/// the first input index and the weights (summing to 1) of consecutive inputs.
#[derive(Clone, Debug)]
pub struct AreaWeights {
    pub start: Vec<usize>,
    pub weights: Vec<Vec<f32>>,
}

impl AreaWeights {
    pub fn new(n_in: usize, n_out: usize) -> AreaWeights {
        let scale = n_in as f64 / n_out as f64;
        let mut start = Vec::with_capacity(n_out);
        let mut weights = Vec::with_capacity(n_out);
        for i in 0..n_out {
            let (a, b) = (i as f64 * scale, (i + 1) as f64 * scale);
            let first = a.floor() as usize;
            let last = (b.ceil() as usize).min(n_in);
            let w: Vec<f64> = (first..last)
                .map(|j| (b.min(j as f64 + 1.0) - a.max(j as f64)).max(0.0))
                .collect();
            let sum: f64 = w.iter().sum();
            start.push(first);
            weights.push(w.iter().map(|v| (v / sum) as f32).collect());
        }
        AreaWeights { start, weights }
    }
}

/// Area resampling of the `area` (in the plane's pixels) of a plane with `BPP`
/// bytes a pixel: calls `emit` with each output pixel's index and the averages
/// of its `BPP` bytes, in raster order.
fn resample<const BPP: usize>(
    plane: &Plane,
    area: Crop,
    w: &AreaWeights,
    mut emit: impl FnMut(usize, &[f32]),
) {
    let res = w.start.len();
    // Vertically first: that pass runs over whole rows of bytes, all lanes at
    // once and vectorised, and leaves only `res` rows for the horizontal pass.
    let mut sums = vec![0f32; area.size * BPP];
    let mut rows = Vec::new();
    for (oy, (&first, wy)) in w.start.iter().zip(&w.weights).enumerate() {
        rows.clear();
        rows.extend((0..wy.len()).map(|k| {
            let start = (area.y + first + k) * plane.stride + area.x * BPP;
            &plane.data[start..start + sums.len()]
        }));
        weighted_sum(&mut sums, &rows, wy);
        for (ox, (&first, wx)) in w.start.iter().zip(&w.weights).enumerate() {
            let mut pixel = [0f32; BPP];
            for (&wk, src) in wx.iter().zip(sums[first * BPP..].chunks_exact(BPP)) {
                for (p, &s) in pixel.iter_mut().zip(src) {
                    *p += wk * s;
                }
            }
            emit(oy * res + ox, &pixel);
        }
    }
}

/// `sums = Σ weights[k] · rows[k]`, lane by lane, adding the rows in order:
/// the crop's inner loop.
fn weighted_sum(sums: &mut [f32], rows: &[&[u8]], weights: &[f32]) {
    // AVX2 doubles the vectors' width and widens bytes to floats in fewer
    // steps; it cut the crop's time by a fifth (I420) to a half (BGRx) at 720p
    // on the build machine. The default x86-64 target only assumes SSE2, so
    // the same loop is built a second time for AVX2 and chosen at run time
    // (a cached check).
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { weighted_sum_avx2(sums, rows, weights) };
    }
    weighted_sum_portable(sums, rows, weights)
}

/// `weighted_sum_portable` built for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn weighted_sum_avx2(sums: &mut [f32], rows: &[&[u8]], weights: &[f32]) {
    weighted_sum_portable(sums, rows, weights)
}

// Always inlined, so that `weighted_sum_avx2` holds a copy built for AVX2.
#[inline(always)]
fn weighted_sum_portable(sums: &mut [f32], rows: &[&[u8]], weights: &[f32]) {
    // A block of lanes at a time through all the rows, rather than one row at
    // a time: the frame comes from memory, and this asks for a cache line of
    // every row at once, while the block's sums stay in registers or L1.
    const BLOCK: usize = 64;
    let whole = sums.len() / BLOCK * BLOCK;
    let (blocks, tail) = sums.split_at_mut(whole);
    for (b, out) in blocks.chunks_exact_mut(BLOCK).enumerate() {
        let mut block = [0f32; BLOCK];
        for (row, &w) in rows.iter().zip(weights) {
            add_weighted(&mut block, &row[b * BLOCK..(b + 1) * BLOCK], w);
        }
        out.copy_from_slice(&block);
    }
    tail.fill(0.0);
    for (row, &w) in rows.iter().zip(weights) {
        add_weighted(tail, &row[whole..], w);
    }
}

/// `sums += w · src`, lane by lane.
#[inline(always)]
fn add_weighted(sums: &mut [f32], src: &[u8], w: f32) {
    for (s, &p) in sums.iter_mut().zip(src) {
        *s += w * p as f32;
    }
}

/// The crop resampled to `res`×`res`, as planar sRGB in [0, 1] (3 × res × res).
pub fn sample_crop(frame: &Frame, crop: Crop, res: usize) -> Vec<f32> {
    let n = res * res;
    // R, G, B or Y, Cb, Cr in 8-bit units, planar.
    let mut out = vec![0f32; 3 * n];
    for pass in frame.format.passes() {
        let area = crop.in_plane(pass.subsample);
        let w = AreaWeights::new(area.size, res);
        let plane = &frame.planes[pass.plane];
        let emit = |i: usize, pixel: &[f32]| {
            for (lane, &v) in pass.lanes.iter().zip(pixel) {
                if let Some(c) = *lane {
                    out[c * n + i] = v;
                }
            }
        };
        match pass.lanes.len() {
            1 => resample::<1>(plane, area, &w, emit),
            2 => resample::<2>(plane, area, &w, emit),
            3 => resample::<3>(plane, area, &w, emit),
            4 => resample::<4>(plane, area, &w, emit),
            bpp => unreachable!("no format has {bpp} bytes a pixel"),
        }
    }
    if frame.format.is_yuv() {
        // Averaging Y, Cb and Cr and then converting equals averaging RGB: the
        // conversion is affine.
        for i in 0..n {
            let rgb = frame.matrix.to_rgb(out[i], out[n + i], out[2 * n + i]);
            for (c, v) in rgb.into_iter().enumerate() {
                out[c * n + i] = v;
            }
        }
    } else {
        out.iter_mut().for_each(|v| *v /= 255.0);
    }
    out
}

/// Constant of the gain `g`: keeps dark regions from amplifying noise.
const GAIN_EPSILON: f32 = 0.02;
/// Largest gain applied to the frame's detail, and the most the relit image may
/// brighten the input (plus [`INVENTED_LIGHT`]).
const MAX_GAIN: f32 = 4.0;
/// Luma (sRGB, [0, 1]) the relit image may add where the input is black. The
/// network has learnt its person's face and can draw it into darkness; light the
/// input does not carry is invented, so it is bounded to about 1 level in 8 bits.
const INVENTED_LIGHT: f32 = 0.004;

/// Rec. 709 luma of pixel `i` of a planar image of `n` pixels a channel.
fn luma(img: &[f32], n: usize, i: usize) -> f32 {
    0.2126 * img[i] + 0.7152 * img[n + i] + 0.0722 * img[2 * n + i]
}

/// Mean luma of a planar sRGB image, 3 × n.
pub fn mean_luma(img: &[f32]) -> f32 {
    let n = img.len() / 3;
    if n == 0 {
        return 0.0;
    }
    (0..n).map(|i| luma(img, n, i)).sum::<f32>() / n as f32
}

/// The lighting change at network resolution, ready to be applied to a frame:
/// per output channel (R, G, B or Y, Cb, Cr in 8-bit units) a pixel `v` becomes
/// `R + g · (v − I)`, with R the relit image, I the network's input and g the gain
/// of the frame's detail.
pub struct LightingChange {
    res: usize,
    base: [Vec<f32>; 3],
    input: [Vec<f32>; 3],
    /// In RGB, each channel's own gain, so the change is a pure per-channel gain
    /// of the frame (`R = g · I`): no halo at edges sharper than the network sees.
    /// In YUV, the luma gain for all three.
    gain: [Vec<f32>; 3],
}

impl LightingChange {
    /// From the network's input and output (planar sRGB in [0, 1], 3 × res × res),
    /// expressed in the channels of `format`.
    pub fn new(
        input: &[f32],
        relit: &[f32],
        res: usize,
        format: PixelFormat,
        matrix: YuvMatrix,
    ) -> LightingChange {
        let n = res * res;
        let relit = smooth_gain_relit(input, &bound_invented_light(input, relit, n), res);
        let ratio = |r: f32, i: f32| ((r + GAIN_EPSILON) / (i + GAIN_EPSILON)).clamp(0.0, MAX_GAIN);
        let gain = if format.is_yuv() {
            let luma_gain: Vec<f32> = (0..n)
                .map(|i| ratio(luma(&relit, n, i), luma(input, n, i)))
                .collect();
            [luma_gain.clone(), luma_gain.clone(), luma_gain]
        } else {
            [0, 1, 2].map(|c| {
                (c * n..(c + 1) * n)
                    .map(|i| ratio(relit[i], input[i]))
                    .collect()
            })
        };
        let to_channels = |img: &[f32]| -> [Vec<f32>; 3] {
            if format.is_yuv() {
                let mut ch = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
                for i in 0..n {
                    let yuv = matrix.from_rgb([img[i], img[n + i], img[2 * n + i]]);
                    for c in 0..3 {
                        ch[c][i] = yuv[c];
                    }
                }
                ch
            } else {
                [0, 1, 2].map(|c| img[c * n..(c + 1) * n].iter().map(|v| v * 255.0).collect())
            }
        };
        LightingChange {
            res,
            base: to_channels(&relit),
            input: to_channels(input),
            gain,
        }
    }

    /// Applies the change to the crop of `frame`. Within `feather` pixels of a
    /// crop edge that lies inside the frame, the change fades out so the crop
    /// leaves no seam.
    pub fn apply(&self, frame: &mut FrameMut, crop: Crop, feather: usize) {
        self.apply_faded(frame, crop, feather, 1.0);
    }

    /// [`LightingChange::apply`], shown at `strength` in [0, 1] (a face fading in or out).
    pub fn apply_faded(&self, frame: &mut FrameMut, crop: Crop, feather: usize, strength: f32) {
        let fade = Fade::new(crop, frame.width, frame.height, feather, strength);
        for pass in frame.format.passes() {
            let (data, stride) = (&mut *frame.planes[pass.plane].0, frame.planes[pass.plane].1);
            let (area, sub) = (crop.in_plane(pass.subsample), pass.subsample);
            match *pass.lanes {
                [a] => self.paste([a], data, stride, area, sub, &fade),
                [a, b] => self.paste([a, b], data, stride, area, sub, &fade),
                [a, b, c] => self.paste([a, b, c], data, stride, area, sub, &fade),
                [a, b, c, d] => self.paste([a, b, c, d], data, stride, area, sub, &fade),
                _ => unreachable!("no format has {} bytes a pixel", pass.lanes.len()),
            }
        }
    }

    /// Applies the change to the `area` (in the plane's pixels) of one plane
    /// whose `BPP` bytes a pixel hold the channels `lanes`. Each row of the area
    /// is one flat run of bytes ("lanes"), whatever channels they hold, so the
    /// loop over it vectorises.
    fn paste<const BPP: usize>(
        &self,
        lanes: [Option<usize>; BPP],
        data: &mut [u8],
        stride: usize,
        area: Crop,
        subsample: usize,
        fade: &Fade,
    ) {
        let wx: Vec<f32> = (0..area.size)
            .map(|i| fade.weight_x((area.x + i) * subsample))
            .collect();
        // Columns and rows where the fade is zero keep their bytes, as they
        // must even where the maps are not finite. The fade rises from each
        // inner edge, so such columns are at the ends and are left out. Among
        // the others, the product of two positive weights (each at least
        // 0.5 / feather) is never zero, so every byte left changes as it did.
        let positive = |w: &f32| *w > 0.0;
        let (Some(first), Some(last)) =
            (wx.iter().position(positive), wx.iter().rposition(positive))
        else {
            return;
        };
        let columns = first..last + 1;
        let taps = taps(self.res, area.size);
        // Per lane; zero on padding, whose maps are zero too, so v + 0 · (0 − v)
        // leaves those bytes as they are.
        let lane_wx: Vec<f32> = wx[columns.clone()]
            .iter()
            .flat_map(|&w| lanes.map(|l| if l.is_some() { w } else { 0.0 }))
            .collect();
        let mut grid = GridRows::new(lane_wx.len());
        for (j, &(ly, ty)) in taps.iter().enumerate() {
            let wy = fade.weight_y((area.y + j) * subsample);
            if wy <= 0.0 {
                continue;
            }
            let (top, bottom) = grid.at(ly, |r, maps| {
                self.interpolate_row(r, lanes, &taps[columns.clone()], maps)
            });
            let start = (area.y + j) * stride + (area.x + first) * BPP;
            blend_row(
                &mut data[start..start + lane_wx.len()],
                &lane_wx,
                wy,
                ty,
                top,
                bottom,
            );
        }
    }

    /// Row `r` of the maps, interpolated across the area at every lane: the
    /// horizontal half of the bilinear upsampling.
    fn interpolate_row<const BPP: usize>(
        &self,
        r: usize,
        lanes: [Option<usize>; BPP],
        taps: &[(usize, f32)],
        out: &mut Maps,
    ) {
        let row = r * self.res..(r + 1) * self.res;
        // Per lane of a pixel, the rows it reads of the base, gain and input.
        let maps = lanes.map(|lane| {
            lane.map(|c| {
                [&self.base[c], &self.gain[c], &self.input[c]].map(|map| &map[row.clone()])
            })
        });
        // a + (b − a) · t, with a and b − a (per map and lane) those of a map
        // column that the next few pixels share. They stay zero on padding.
        let (mut column, mut a, mut d) = (None, [[0f32; BPP]; 3], [[0f32; BPP]; 3]);
        let outs = (out.base.chunks_exact_mut(BPP))
            .zip(out.gain.chunks_exact_mut(BPP))
            .zip(out.input.chunks_exact_mut(BPP));
        for (&(lx, tx), ((base, gain), input)) in taps.iter().zip(outs) {
            if column != Some(lx) {
                column = Some(lx);
                for (lane, rows) in maps.iter().enumerate() {
                    if let Some(rows) = rows {
                        for (m, row) in rows.iter().enumerate() {
                            (a[m][lane], d[m][lane]) = (row[lx], row[lx + 1] - row[lx]);
                        }
                    }
                }
            }
            for ((out, a), d) in [base, gain, input].into_iter().zip(&a).zip(&d) {
                for ((o, a), d) in out.iter_mut().zip(a).zip(d) {
                    *o = a + d * tx;
                }
            }
        }
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

/// Radius, as a fraction of the network's resolution, of the blur that keeps the
/// network's colour noise out of the lighting change.
const GAIN_SMOOTHING: f32 = 0.06;

/// The relit image as the input times a smooth per-channel gain: the network's
/// lighting change without its pixel-scale colour noise, which the transfer
/// would otherwise paint onto the skin as blotches. The gain is blurred in the
/// log domain over `GAIN_SMOOTHING` of the image.
fn smooth_gain_relit(input: &[f32], relit: &[f32], res: usize) -> Vec<f32> {
    let n = res * res;
    let radius = ((GAIN_SMOOTHING * res as f32).round() as usize).max(1);
    let mut out = vec![0f32; 3 * n];
    for c in 0..3 {
        let (i, r) = (&input[c * n..(c + 1) * n], &relit[c * n..(c + 1) * n]);
        let log_gain: Vec<f32> = i
            .iter()
            .zip(r)
            .map(|(i, r)| {
                ((r + GAIN_EPSILON) / (i + GAIN_EPSILON))
                    .clamp(1.0 / MAX_GAIN, MAX_GAIN)
                    .ln()
            })
            .collect();
        let smooth = box_blur(&box_blur(&log_gain, res, radius), res, radius);
        for (k, o) in out[c * n..(c + 1) * n].iter_mut().enumerate() {
            *o = (i[k] + GAIN_EPSILON) * smooth[k].exp() - GAIN_EPSILON;
        }
    }
    out
}

/// A box blur of a res × res field, `radius` each way, shrinking at the borders.
fn box_blur(field: &[f32], res: usize, radius: usize) -> Vec<f32> {
    let along = |src: &[f32], at: &dyn Fn(usize, usize) -> usize| {
        let mut out = vec![0f32; src.len()];
        let mut prefix = vec![0f32; res + 1];
        for line in 0..res {
            for k in 0..res {
                prefix[k + 1] = prefix[k] + src[at(line, k)];
            }
            for k in 0..res {
                let (lo, hi) = (k.saturating_sub(radius), (k + radius + 1).min(res));
                out[at(line, k)] = (prefix[hi] - prefix[lo]) / (hi - lo) as f32;
            }
        }
        out
    };
    let rows = along(field, &|y, x| y * res + x);
    along(&rows, &|x, y| y * res + x)
}

/// Bilinear taps from `size` samples of a frame onto `res` samples of a map:
/// per frame sample, the lower map index and the weight of the upper one.
fn taps(res: usize, size: usize) -> Vec<(usize, f32)> {
    let scale = res as f32 / size as f32;
    (0..size)
        .map(|i| {
            let p = ((i as f32 + 0.5) * scale - 0.5).clamp(0.0, (res - 1) as f32);
            let lo = (p.floor() as usize).min(res.saturating_sub(2));
            (lo, p - lo as f32)
        })
        .collect()
}

/// The three maps at one map row, interpolated to every lane of an area's row.
struct Maps {
    base: Vec<f32>,
    gain: Vec<f32>,
    input: Vec<f32>,
}

/// Two consecutive rows of `Maps`, kept while the output rows they serve
/// (about `size / res` of them) go by. Row `r` lives in slot `r % 2`.
struct GridRows {
    held: [Option<usize>; 2],
    slots: [Maps; 2],
}

impl GridRows {
    fn new(lanes: usize) -> GridRows {
        let maps = || Maps {
            base: vec![0.0; lanes],
            gain: vec![0.0; lanes],
            input: vec![0.0; lanes],
        };
        GridRows {
            held: [None; 2],
            slots: [maps(), maps()],
        }
    }

    /// Rows `ly` and `ly + 1`, filling in with `fill` those not held.
    fn at(&mut self, ly: usize, fill: impl Fn(usize, &mut Maps)) -> (&Maps, &Maps) {
        for r in [ly, ly + 1] {
            if self.held[r % 2] != Some(r) {
                fill(r, &mut self.slots[r % 2]);
                self.held[r % 2] = Some(r);
            }
        }
        (&self.slots[ly % 2], &self.slots[(ly + 1) % 2])
    }
}

/// Blends one row of lanes: the vertical half of the bilinear upsampling, then
/// `v + w · (R + g · (v − I) − v)` rounded, with `w` the fade, in exactly the
/// operations of a per-pixel bilinear sample so the bytes do not change.
fn blend_row(row: &mut [u8], wx: &[f32], wy: f32, ty: f32, top: &Maps, bottom: &Maps) {
    // As in `weighted_sum`: AVX2, where the CPU has it, made the paste 1.7-1.8
    // times as fast on the build machine. The results are the same, as both
    // builds run the same IEEE operations in the same order (Rust never fuses a
    // multiply and an add on its own).
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { blend_row_avx2(row, wx, wy, ty, top, bottom) };
    }
    blend_row_portable(row, wx, wy, ty, top, bottom)
}

/// `blend_row_portable` built for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn blend_row_avx2(row: &mut [u8], wx: &[f32], wy: f32, ty: f32, top: &Maps, bottom: &Maps) {
    blend_row_portable(row, wx, wy, ty, top, bottom)
}

// Always inlined, so that `blend_row_avx2` holds a copy built for AVX2.
#[inline(always)]
fn blend_row_portable(row: &mut [u8], wx: &[f32], wy: f32, ty: f32, top: &Maps, bottom: &Maps) {
    let uy = 1.0 - ty;
    // Equal lengths up front let the compiler drop the bounds checks.
    let n = row.len();
    let (wx, top_base, top_gain, top_input) =
        (&wx[..n], &top.base[..n], &top.gain[..n], &top.input[..n]);
    let (bottom_base, bottom_gain, bottom_input) =
        (&bottom.base[..n], &bottom.gain[..n], &bottom.input[..n]);
    for k in 0..n {
        let v = row[k] as f32;
        let base = top_base[k] * uy + bottom_base[k] * ty;
        let gain = top_gain[k] * uy + bottom_gain[k] * ty;
        let input = top_input[k] * uy + bottom_input[k] * ty;
        let relit = base + gain * (v - input);
        let w = wy * wx[k];
        row[k] = round_to_u8(v + w * (relit - v));
    }
}

/// `x.round().clamp(0.0, 255.0) as u8` (NaN to 0 as there) in operations that
/// vectorise: `f32::round` is a call to libm's `roundf` on the default x86-64
/// target, which lacks SSE4.1's rounding instruction, and a float to integer
/// `as` saturates, which costs a compare and a select per lane.
// Always inlined, like `blend_row_portable`, into the AVX2 build.
#[inline(always)]
fn round_to_u8(x: f32) -> u8 {
    // Clamping first changes nothing, as rounding is monotone and 0 and 255 are
    // whole. Comparisons with NaN fail, so NaN becomes 0.
    let c = if x > 0.0 { x } else { 0.0 };
    let c = if c < 255.0 { c } else { 255.0 };
    // Adding 2^23 leaves nothing below the units, so the sum is c rounded to
    // the nearest whole number, ties to even, and that number is in its low
    // bits. `round` takes ties away from zero instead: where c is exactly half
    // above the even neighbour, add one. (`c - whole` is exact.)
    const SHIFT: f32 = 8_388_608.0;
    let shifted = c + SHIFT;
    let whole = shifted - SHIFT;
    (shifted.to_bits() + u32::from(c - whole == 0.5)) as u8
}

/// Weight of the lighting change by distance to the crop's inner edges.
struct Fade {
    crop: Crop,
    feather: f32,
    /// How much of the change shows anywhere, in [0, 1].
    strength: f32,
    /// Which crop edges lie inside the frame: left, right, top, bottom.
    inner: [bool; 4],
}

impl Fade {
    fn new(crop: Crop, width: usize, height: usize, feather: usize, strength: f32) -> Fade {
        Fade {
            crop,
            feather: feather as f32,
            strength: strength.clamp(0.0, 1.0),
            inner: [
                crop.x > 0,
                crop.x + crop.size < width,
                crop.y > 0,
                crop.y + crop.size < height,
            ],
        }
    }

    fn ramp(&self, from_low: f32, from_high: f32, low_inner: bool, high_inner: bool) -> f32 {
        if self.feather <= 0.0 {
            return 1.0;
        }
        let mut w: f32 = 1.0;
        if low_inner {
            w = w.min(from_low / self.feather);
        }
        if high_inner {
            w = w.min(from_high / self.feather);
        }
        // Smoothstep: no kink where the fade starts or ends, which the eye reads as an edge.
        let t = w.clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    }

    /// `x` in frame pixels.
    fn weight_x(&self, x: usize) -> f32 {
        let from_left = x as f32 - self.crop.x as f32 + 0.5;
        let from_right = (self.crop.x + self.crop.size) as f32 - x as f32 - 0.5;
        self.ramp(from_left, from_right, self.inner[0], self.inner[1])
    }

    fn weight_y(&self, y: usize) -> f32 {
        let from_top = y as f32 - self.crop.y as f32 + 0.5;
        let from_bottom = (self.crop.y + self.crop.size) as f32 - y as f32 - 0.5;
        self.strength * self.ramp(from_top, from_bottom, self.inner[2], self.inner[3])
    }
}

#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;
