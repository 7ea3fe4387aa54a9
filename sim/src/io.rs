//! File formats: PNG images, NumPy `.npy` arrays and YUV4MPEG2 (`.y4m`) video.
//!
//! `.npy` is what the Python trainer memory-maps. `.y4m` is an ordinary,
//! uncompressed video file that GStreamer (`y4mdec`), FFmpeg and players
//! read, so recordings are lossless and byte-for-byte reproducible.

use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, Read, Write};
use std::path::Path;

use crate::monitor::RgbImage;

pub fn write_png(path: &Path, img: &RgbImage) -> io::Result<()> {
    let w = BufWriter::new(File::create(path)?);
    let mut enc = png::Encoder::new(w, img.width as u32, img.height as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(io::Error::other)?;
    writer.write_image_data(&img.data).map_err(io::Error::other)
}

pub fn read_png(path: &Path) -> io::Result<RgbImage> {
    let dec = png::Decoder::new(BufReader::new(File::open(path)?));
    let mut reader = dec.read_info().map_err(io::Error::other)?;
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).map_err(io::Error::other)?;
    if info.color_type != png::ColorType::Rgb || info.bit_depth != png::BitDepth::Eight {
        return Err(io::Error::other(format!(
            "{}: expected 8-bit RGB PNG",
            path.display()
        )));
    }
    buf.truncate(info.buffer_size());
    Ok(RgbImage {
        width: info.width as usize,
        height: info.height as usize,
        data: buf,
    })
}

/// Element types that `.npy` files here hold.
pub trait NpyElement: Copy {
    const DESCR: &'static str;
    fn write_le(values: &[Self], out: &mut impl Write) -> io::Result<()>;
    fn read_le(bytes: &[u8]) -> Vec<Self>;
}

macro_rules! npy_element {
    ($t:ty, $descr:expr) => {
        impl NpyElement for $t {
            const DESCR: &'static str = $descr;
            fn write_le(values: &[Self], out: &mut impl Write) -> io::Result<()> {
                for v in values {
                    out.write_all(&v.to_le_bytes())?;
                }
                Ok(())
            }
            fn read_le(bytes: &[u8]) -> Vec<Self> {
                bytes
                    .chunks_exact(std::mem::size_of::<$t>())
                    .map(|c| <$t>::from_le_bytes(c.try_into().unwrap()))
                    .collect()
            }
        }
    };
}
npy_element!(u8, "|u1");
npy_element!(f32, "<f4");
npy_element!(f64, "<f8");
npy_element!(i64, "<i8");

fn npy_header(descr: &str, shape: &[usize]) -> Vec<u8> {
    npy_header_at_least(descr, shape, 0)
}

/// The header, padded to at least `min_len` bytes (and a multiple of 64).
fn npy_header_at_least(descr: &str, shape: &[usize], min_len: usize) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_txt = if shape.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut dict =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_txt}, }}");
    // Magic (6) + version (2) + length (2) + dict + newline, padded to 64 bytes.
    let total = 10 + dict.len() + 1;
    dict.push_str(&" ".repeat(total.max(min_len).div_ceil(64) * 64 - total));
    dict.push('\n');
    let mut h = b"\x93NUMPY\x01\x00".to_vec();
    h.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    h.extend_from_slice(dict.as_bytes());
    h
}

/// Streams an array of known shape to a `.npy` file, first axis by first axis.
pub struct NpyWriter<T: NpyElement> {
    out: BufWriter<File>,
    expected: usize,
    written: usize,
    _t: std::marker::PhantomData<T>,
}

impl<T: NpyElement> NpyWriter<T> {
    pub fn create(path: &Path, shape: &[usize]) -> io::Result<Self> {
        let mut out = BufWriter::new(File::create(path)?);
        out.write_all(&npy_header(T::DESCR, shape))?;
        Ok(Self {
            out,
            expected: shape.iter().product(),
            written: 0,
            _t: std::marker::PhantomData,
        })
    }

    pub fn append(&mut self, values: &[T]) -> io::Result<()> {
        self.written += values.len();
        if self.written > self.expected {
            return Err(io::Error::other("more values than the array's shape holds"));
        }
        T::write_le(values, &mut self.out)
    }

    pub fn finish(mut self) -> io::Result<()> {
        if self.written != self.expected {
            return Err(io::Error::other(format!(
                "wrote {} of {} values",
                self.written, self.expected
            )));
        }
        self.out.flush()
    }
}

/// Streams an array whose first axis grows until it is finished, row by row
/// (a row being `row_shape`): the header, written first with room for any
/// length, is rewritten with the final length by [`GrowingNpyWriter::finish`].
pub struct GrowingNpyWriter<T: NpyElement> {
    out: BufWriter<File>,
    row_shape: Vec<usize>,
    rows: usize,
    header_len: usize,
    _t: std::marker::PhantomData<T>,
}

impl<T: NpyElement> GrowingNpyWriter<T> {
    pub fn create(path: &Path, row_shape: &[usize]) -> io::Result<Self> {
        let mut out = BufWriter::new(File::create(path)?);
        let header = Self::header(row_shape, usize::MAX, 0);
        out.write_all(&header)?;
        Ok(Self {
            out,
            row_shape: row_shape.to_vec(),
            rows: 0,
            header_len: header.len(),
            _t: std::marker::PhantomData,
        })
    }

    fn header(row_shape: &[usize], rows: usize, min_len: usize) -> Vec<u8> {
        let shape: Vec<usize> = std::iter::once(rows)
            .chain(row_shape.iter().copied())
            .collect();
        npy_header_at_least(T::DESCR, &shape, min_len)
    }

    /// Appends one row of `row_shape`'s size.
    pub fn append(&mut self, row: &[T]) -> io::Result<()> {
        if row.len() != self.row_shape.iter().product::<usize>() {
            return Err(io::Error::other(format!(
                "a row of {} values is not of shape {:?}",
                row.len(),
                self.row_shape
            )));
        }
        self.rows += 1;
        T::write_le(row, &mut self.out)
    }

    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Writes the final length into the header and flushes.
    pub fn finish(mut self) -> io::Result<()> {
        use std::io::{Seek, SeekFrom};
        self.out.flush()?;
        let header = Self::header(&self.row_shape, self.rows, self.header_len);
        debug_assert_eq!(header.len(), self.header_len);
        let mut file = self.out.into_inner().map_err(|e| e.into_error())?;
        file.seek(SeekFrom::Start(0))?;
        file.write_all(&header)?;
        file.sync_all()
    }
}

pub fn write_npy<T: NpyElement>(path: &Path, shape: &[usize], values: &[T]) -> io::Result<()> {
    let mut w = NpyWriter::create(path, shape)?;
    w.append(values)?;
    w.finish()
}

/// Reads a `.npy` array written by [`write_npy`]: its shape and values.
pub fn read_npy<T: NpyElement>(path: &Path) -> io::Result<(Vec<usize>, Vec<T>)> {
    let mut bytes = Vec::new();
    File::open(path)?.read_to_end(&mut bytes)?;
    if !bytes.starts_with(b"\x93NUMPY\x01\x00") {
        return Err(io::Error::other("not a version 1 .npy file"));
    }
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + len]).map_err(io::Error::other)?;
    if !header.contains(&format!("'descr': '{}'", T::DESCR)) {
        return Err(io::Error::other(format!(
            "{}: element type is not {}",
            path.display(),
            T::DESCR
        )));
    }
    let shape_txt = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| io::Error::other("no shape in .npy header"))?;
    let shape: Vec<usize> = shape_txt
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().map_err(io::Error::other))
        .collect::<io::Result<_>>()?;
    Ok((shape, T::read_le(&bytes[10 + len..])))
}

/// Chroma layout of a `.y4m` file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Chroma {
    /// 4:2:0, as webcams deliver.
    C420,
    /// 4:4:4, as lossless screen capture keeps.
    C444,
}

/// BT.601 limited-range conversion, the GStreamer default for frames up to 576 lines.
fn rgb_to_ycbcr(r: u8, g: u8, b: u8) -> (f32, f32, f32) {
    let (r, g, b) = (r as f32 / 255.0, g as f32 / 255.0, b as f32 / 255.0);
    let y = 0.299 * r + 0.587 * g + 0.114 * b;
    let cb = (b - y) / 1.772;
    let cr = (r - y) / 1.402;
    (16.0 + 219.0 * y, 128.0 + 224.0 * cb, 128.0 + 224.0 * cr)
}

/// Inverse of the conversion the writer uses (BT.601, limited range).
pub fn ycbcr_to_rgb(y: u8, cb: u8, cr: u8) -> [u8; 3] {
    let y = (y as f32 - 16.0) / 219.0;
    let cb = (cb as f32 - 128.0) / 224.0;
    let cr = (cr as f32 - 128.0) / 224.0;
    let r = y + 1.402 * cr;
    let g = y - 0.344_136 * cb - 0.714_136 * cr;
    let b = y + 1.772 * cb;
    [r, g, b].map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
}

fn to_u8(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// Writes RGB frames as a YUV4MPEG2 video (BT.601, limited range; 4:2:0 chroma is
/// the mean of each 2×2 block, sited at its centre as `C420jpeg` says).
pub struct Y4mWriter {
    out: BufWriter<File>,
    width: usize,
    height: usize,
    chroma: Chroma,
}

impl Y4mWriter {
    pub fn create(
        path: &Path,
        width: usize,
        height: usize,
        fps: u32,
        chroma: Chroma,
    ) -> io::Result<Self> {
        if chroma == Chroma::C420 && (!width.is_multiple_of(2) || !height.is_multiple_of(2)) {
            return Err(io::Error::other("4:2:0 needs even frame sizes"));
        }
        let mut out = BufWriter::new(File::create(path)?);
        let c = match chroma {
            Chroma::C420 => "420jpeg",
            Chroma::C444 => "444",
        };
        // XCOLORRANGE is the one colour tag YUV4MPEG2 readers know (FFmpeg's); it has
        // none for the matrix. GStreamer 1.22's y4mdec reads neither it nor the chroma
        // siting of `C`: it takes frames over 576 lines as BT.709 with MPEG-2 siting,
        // so pipelines that read these files with it set
        // `colorimetry=bt601,chroma-site=jpeg` themselves (as the element's test
        // harness does, `tests/support/src/recording.rs`).
        writeln!(
            out,
            "YUV4MPEG2 W{width} H{height} F{fps}:1 Ip A1:1 C{c} XCOLORRANGE=LIMITED"
        )?;
        Ok(Self {
            out,
            width,
            height,
            chroma,
        })
    }

    pub fn write(&mut self, img: &RgbImage) -> io::Result<()> {
        if img.width != self.width || img.height != self.height {
            return Err(io::Error::other("frame size differs from the video's"));
        }
        let (w, h) = (self.width, self.height);
        let mut y = vec![0u8; w * h];
        let mut cb = vec![0f32; w * h];
        let mut cr = vec![0f32; w * h];
        for i in 0..w * h {
            let (yy, u, v) =
                rgb_to_ycbcr(img.data[3 * i], img.data[3 * i + 1], img.data[3 * i + 2]);
            y[i] = to_u8(yy);
            cb[i] = u;
            cr[i] = v;
        }
        self.out.write_all(b"FRAME\n")?;
        self.out.write_all(&y)?;
        match self.chroma {
            Chroma::C444 => {
                for plane in [&cb, &cr] {
                    let bytes: Vec<u8> = plane.iter().map(|&v| to_u8(v)).collect();
                    self.out.write_all(&bytes)?;
                }
            }
            Chroma::C420 => {
                for plane in [&cb, &cr] {
                    let mut bytes = Vec::with_capacity(w * h / 4);
                    for yy in (0..h).step_by(2) {
                        for xx in (0..w).step_by(2) {
                            let s = plane[yy * w + xx]
                                + plane[yy * w + xx + 1]
                                + plane[(yy + 1) * w + xx]
                                + plane[(yy + 1) * w + xx + 1];
                            bytes.push(to_u8(0.25 * s));
                        }
                    }
                    self.out.write_all(&bytes)?;
                }
            }
        }
        Ok(())
    }

    pub fn finish(mut self) -> io::Result<()> {
        self.out.flush()
    }
}

/// A frame's Y'CbCr planes (BT.601, limited range, as [`Y4mWriter`] writes them)
/// to RGB: each chroma sample is used for every pixel it was averaged from. The
/// one decoder of [`Y4mReader`] and of anything whose figures are compared with
/// frames it read.
pub fn ycbcr_planes_to_rgb(
    y: &[u8],
    cb: &[u8],
    cr: &[u8],
    width: usize,
    height: usize,
    chroma: Chroma,
) -> RgbImage {
    let (w, h) = (width, height);
    let (cw, ch) = match chroma {
        Chroma::C420 => (w / 2, h / 2),
        Chroma::C444 => (w, h),
    };
    let mut img = RgbImage::new(w, h);
    for yy in 0..h {
        for xx in 0..w {
            let ci = (yy * ch / h) * cw + xx * cw / w;
            let rgb = ycbcr_to_rgb(y[yy * w + xx], cb[ci], cr[ci]);
            img.data[(yy * w + xx) * 3..(yy * w + xx) * 3 + 3].copy_from_slice(&rgb);
        }
    }
    img
}

/// Reads the frames of a `.y4m` video written by [`Y4mWriter`] back to RGB.
pub struct Y4mReader {
    input: BufReader<File>,
    pub width: usize,
    pub height: usize,
    pub fps: u32,
    pub chroma: Chroma,
}

impl Y4mReader {
    pub fn open(path: &Path) -> io::Result<Self> {
        let mut input = BufReader::new(File::open(path)?);
        let mut line = String::new();
        input.read_line(&mut line)?;
        let mut r = Y4mReader {
            input,
            width: 0,
            height: 0,
            fps: 0,
            chroma: Chroma::C420,
        };
        if !line.starts_with("YUV4MPEG2") {
            return Err(io::Error::other("not a YUV4MPEG2 file"));
        }
        for tok in line.split_whitespace().skip(1) {
            let (k, v) = tok.split_at(1);
            match k {
                "W" => r.width = v.parse().map_err(io::Error::other)?,
                "H" => r.height = v.parse().map_err(io::Error::other)?,
                "F" => {
                    r.fps = v
                        .split(':')
                        .next()
                        .unwrap_or("0")
                        .parse()
                        .map_err(io::Error::other)?
                }
                "C" => {
                    r.chroma = if v.starts_with("444") {
                        Chroma::C444
                    } else {
                        Chroma::C420
                    }
                }
                _ => {}
            }
        }
        Ok(r)
    }

    /// The next frame, or None at the end.
    pub fn next_frame(&mut self) -> io::Result<Option<RgbImage>> {
        let mut tag = String::new();
        if self.input.read_line(&mut tag)? == 0 {
            return Ok(None);
        }
        let (w, h) = (self.width, self.height);
        let (cw, ch) = match self.chroma {
            Chroma::C420 => (w / 2, h / 2),
            Chroma::C444 => (w, h),
        };
        let mut y = vec![0u8; w * h];
        let mut u = vec![0u8; cw * ch];
        let mut v = vec![0u8; cw * ch];
        self.input.read_exact(&mut y)?;
        self.input.read_exact(&mut u)?;
        self.input.read_exact(&mut v)?;
        Ok(Some(ycbcr_planes_to_rgb(&y, &u, &v, w, h, self.chroma)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_growing_array_reads_back_with_its_final_length() {
        let dir = std::env::temp_dir().join(format!("deskstage-growing-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.npy");
        let mut w = GrowingNpyWriter::<f64>::create(&path, &[2]).unwrap();
        for i in 0..3 {
            w.append(&[i as f64, -(i as f64)]).unwrap();
        }
        assert!(w.append(&[1.0]).is_err());
        w.finish().unwrap();
        let (shape, values) = read_npy::<f64>(&path).unwrap();
        assert_eq!(shape, [3, 2]);
        assert_eq!(values, [0.0, -0.0, 1.0, -1.0, 2.0, -2.0]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn npy_round_trip() {
        let dir = std::env::temp_dir().join(format!("deskstage-npy-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.npy");
        let v: Vec<f32> = (0..24).map(|i| i as f32 * 0.5).collect();
        write_npy(&p, &[2, 3, 4], &v).unwrap();
        let (shape, back) = read_npy::<f32>(&p).unwrap();
        assert_eq!(shape, vec![2, 3, 4]);
        assert_eq!(back, v);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn y4m_round_trip_states_limited_range() {
        let dir = std::env::temp_dir().join(format!("deskstage-y4m-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.y4m");
        // Uniform 2x2 blocks, so 4:2:0 loses nothing but rounding.
        let mut img = RgbImage::new(8, 4);
        for y in 0..4 {
            for x in 0..8 {
                let i = (y * 8 + x) * 3;
                let block = (y / 2 * 4 + x / 2) as u8;
                img.data[i..i + 3].copy_from_slice(&[block * 30, 255 - block * 20, 60 + block]);
            }
        }
        let mut w = Y4mWriter::create(&p, 8, 4, 30, Chroma::C420).unwrap();
        w.write(&img).unwrap();
        w.finish().unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let header = String::from_utf8_lossy(bytes.split(|&b| b == b'\n').next().unwrap());
        assert_eq!(
            header,
            "YUV4MPEG2 W8 H4 F30:1 Ip A1:1 C420jpeg XCOLORRANGE=LIMITED"
        );
        let mut r = Y4mReader::open(&p).unwrap();
        assert_eq!(
            (r.width, r.height, r.fps, r.chroma),
            (8, 4, 30, Chroma::C420)
        );
        let back = r.next_frame().unwrap().unwrap();
        for (a, b) in back.data.iter().zip(&img.data) {
            assert!(
                (*a as i32 - *b as i32).abs() <= 2,
                "{:?} vs {:?}",
                back.data,
                img.data
            );
        }
        assert!(r.next_frame().unwrap().is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn ycbcr_round_trip_is_close() {
        for (r, g, b) in [(0, 0, 0), (255, 255, 255), (200, 120, 40), (10, 200, 90)] {
            let (y, u, v) = rgb_to_ycbcr(r, g, b);
            let back = ycbcr_to_rgb(to_u8(y), to_u8(u), to_u8(v));
            for (a, b) in back.iter().zip([r, g, b]) {
                assert!(
                    (*a as i32 - b as i32).abs() <= 2,
                    "{back:?} vs {:?}",
                    (r, g, b)
                );
            }
        }
    }
}
