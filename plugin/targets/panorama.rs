//! Environment maps as target lights, as the paper uses them: the part of an
//! equirectangular panorama in front of the viewer, `target-fov` wide and half as
//! high (the light grid's 2:1), becomes the monitor's picture.
//!
//! Conventions. The panorama's centre column looks straight ahead; longitude
//! grows to the viewer's right, so its left half is on the viewer's left, as in
//! any panorama viewer. Its top row looks straight up. The screen's column 0 is
//! the user's left (the contract's). `yaw` turns the viewer to the right (the
//! picture moves left on the screen), `pitch` tilts the view up.
//!
//! Tone mapping: each panorama pixel's linear RGB (HDR and EXR as stored; PNG
//! and JPEG decoded from sRGB) is scaled by 2^`exposure` and clipped to [0, 1],
//! the most a monitor shows, before it is averaged into the grid, as a monitor
//! showing the tone-mapped picture would be.
//!
//! The projection integrates, it does not point-sample: a grid cell's value is
//! the mean over its solid angle. Without pitch a cell is a longitude-latitude
//! rectangle of the panorama, and the integral of the piecewise-constant
//! panorama over it is exact (column overlaps times the difference of the sines
//! of the latitudes bounding each row's overlap). With pitch the cells are not
//! rectangles of the panorama; each panorama pixel is then split into parts no
//! larger than a quarter of a cell and each part's solid angle goes to the cell
//! its centre falls in.

use std::f64::consts::PI;
use std::path::Path;

use crate::light::{LIGHT_COLS, LIGHT_ROWS, Light, srgb_to_linear};

pub const DEFAULT_FOV: f64 = 180.0;

/// Where the monitor looks into the panorama, and how bright.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Horizontal field of view in degrees (vertical: half of it).
    pub fov: f64,
    /// Degrees the viewer is turned to the right.
    pub yaw: f64,
    /// Degrees the view is tilted up.
    pub pitch: f64,
    /// Exposure in stops: pixels are scaled by 2^exposure before clipping.
    pub exposure: f64,
}

impl Default for View {
    fn default() -> Self {
        View {
            fov: DEFAULT_FOV,
            yaw: 0.0,
            pitch: 0.0,
            exposure: 0.0,
        }
    }
}

/// An equirectangular panorama in linear RGB.
#[derive(Clone, Debug)]
pub struct Panorama {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
}

/// Whether a path names an environment map format that stores linear light.
pub fn is_hdr_path(path: &Path) -> bool {
    matches!(
        image::ImageFormat::from_path(path),
        Ok(image::ImageFormat::Hdr | image::ImageFormat::OpenExr)
    )
}

impl Panorama {
    /// A panorama from linear RGB pixels, row by row from the top.
    pub fn from_linear(
        width: usize,
        height: usize,
        rgb: Vec<[f32; 3]>,
    ) -> Result<Panorama, String> {
        if width < 2 || height < 1 || rgb.len() != width * height {
            return Err(format!(
                "a panorama needs at least 2 x 1 pixels and one per place ({width} x {height}, {} pixels)",
                rgb.len()
            ));
        }
        if rgb.iter().flatten().any(|v| !v.is_finite() || *v < 0.0) {
            return Err("the panorama has negative, NaN or infinite pixels".into());
        }
        Ok(Panorama { width, height, rgb })
    }

    /// Reads an equirectangular panorama: Radiance `.hdr` and OpenEXR `.exr` as
    /// linear light, PNG and JPEG as sRGB.
    pub fn open(path: &Path) -> Result<Panorama, String> {
        let reader = image::ImageReader::open(path)
            .and_then(|r| r.with_guessed_format())
            .map_err(|e| format!("cannot open environment map {}: {e}", path.display()))?;
        let format = reader.format();
        let linear = matches!(
            format,
            Some(image::ImageFormat::Hdr | image::ImageFormat::OpenExr)
        );
        if !matches!(
            format,
            Some(
                image::ImageFormat::Hdr
                    | image::ImageFormat::OpenExr
                    | image::ImageFormat::Png
                    | image::ImageFormat::Jpeg
            )
        ) {
            return Err(format!(
                "{}: environment maps must be Radiance .hdr, OpenEXR .exr, PNG or JPEG",
                path.display()
            ));
        }
        let image = reader
            .decode()
            .map_err(|e| format!("cannot decode environment map {}: {e}", path.display()))?
            .into_rgb32f();
        let (w, h) = (image.width() as usize, image.height() as usize);
        if w != 2 * h {
            return Err(format!(
                "{} is {w} x {h}: an equirectangular panorama is twice as wide as high",
                path.display()
            ));
        }
        let rgb = image
            .pixels()
            .map(|p| {
                if linear {
                    p.0.map(|v| v.max(0.0))
                } else {
                    p.0.map(srgb_to_linear)
                }
            })
            .collect();
        Panorama::from_linear(w, h, rgb)
            .map_err(|e| format!("environment map {}: {e}", path.display()))
    }

    /// The linear RGB of pixel (`x`, `y`), row 0 at the top.
    pub fn pixel(&self, x: usize, y: usize) -> [f32; 3] {
        self.rgb[y * self.width + x]
    }

    /// The monitor light that shows the panorama through `view`.
    pub fn light(&self, view: &View) -> Light {
        let gain = 2f32.powf(view.exposure as f32);
        let tone = |p: &[f32; 3]| p.map(|v| (v * gain).clamp(0.0, 1.0));
        let fov = view.fov.clamp(1.0, 360.0);
        let (sums, weights) = if view.pitch == 0.0 {
            self.integrate_rectangles(fov, view.yaw, &tone)
        } else {
            self.integrate_rotated(fov, view.yaw, view.pitch, &tone)
        };
        let n = LIGHT_ROWS * LIGHT_COLS;
        let mut out = vec![0f32; 3 * n];
        for cell in 0..n {
            let rgb = if weights[cell] > 0.0 {
                sums[cell].map(|s| (s / weights[cell]) as f32)
            } else {
                // A cell narrower than any part of a pixel: the pixel at its centre.
                let (r, c) = (cell / LIGHT_COLS, cell % LIGHT_COLS);
                let (lon, lat) = cell_centre(fov, r, c);
                let (wlon, wlat) = rotate(lon, lat, view.yaw.to_radians(), view.pitch.to_radians());
                tone(&self.rgb[self.pixel_at(wlon, wlat)])
            };
            for ch in 0..3 {
                out[ch * n + cell] = rgb[ch];
            }
        }
        Light(out)
    }

    /// The pixel holding a direction (radians).
    fn pixel_at(&self, lon: f64, lat: f64) -> usize {
        let u = (lon / (2.0 * PI) + 0.5).rem_euclid(1.0);
        let v = (0.5 - lat / PI).clamp(0.0, 1.0);
        let x = ((u * self.width as f64) as usize).min(self.width - 1);
        let y = ((v * self.height as f64) as usize).min(self.height - 1);
        y * self.width + x
    }

    /// Exact cell integrals without pitch: sums of tone-mapped light times solid
    /// angle, and the cells' solid angles.
    fn integrate_rectangles(
        &self,
        fov: f64,
        yaw: f64,
        tone: &dyn Fn(&[f32; 3]) -> [f32; 3],
    ) -> (Vec<[f64; 3]>, Vec<f64>) {
        let (w, h) = (self.width as f64, self.height as f64);
        // Columns: in panorama pixel units, wrapping around.
        let col_taps: Vec<Vec<(usize, f64)>> = (0..LIGHT_COLS)
            .map(|c| {
                let lon0 = yaw + (c as f64 / LIGHT_COLS as f64 - 0.5) * fov;
                let lon1 = yaw + ((c + 1) as f64 / LIGHT_COLS as f64 - 0.5) * fov;
                let (a, b) = ((lon0 / 360.0 + 0.5) * w, (lon1 / 360.0 + 0.5) * w);
                let mut taps = Vec::new();
                let mut x = a.floor();
                while x < b {
                    let overlap = (x + 1.0).min(b) - x.max(a);
                    if overlap > 0.0 {
                        let i = (x as i64).rem_euclid(self.width as i64) as usize;
                        taps.push((i, overlap));
                    }
                    x += 1.0;
                }
                taps
            })
            .collect();
        // Rows: weight sin(upper) - sin(lower) of the overlap in latitude.
        let row_taps: Vec<Vec<(usize, f64)>> = (0..LIGHT_ROWS)
            .map(|r| {
                let top = (0.5 - r as f64 / LIGHT_ROWS as f64) * fov / 2.0;
                let bottom = (0.5 - (r + 1) as f64 / LIGHT_ROWS as f64) * fov / 2.0;
                (0..self.height)
                    .filter_map(|j| {
                        let ptop = 90.0 - j as f64 * 180.0 / h;
                        let pbottom = 90.0 - (j + 1) as f64 * 180.0 / h;
                        let hi = top.min(ptop);
                        let lo = bottom.max(pbottom);
                        (hi > lo).then(|| (j, hi.to_radians().sin() - lo.to_radians().sin()))
                    })
                    .collect()
            })
            .collect();
        let n = LIGHT_ROWS * LIGHT_COLS;
        let mut sums = vec![[0f64; 3]; n];
        let mut weights = vec![0f64; n];
        for (r, rows) in row_taps.iter().enumerate() {
            for &(j, wr) in rows {
                let line = &self.rgb[j * self.width..(j + 1) * self.width];
                for (c, cols) in col_taps.iter().enumerate() {
                    let cell = r * LIGHT_COLS + c;
                    for &(i, wc) in cols {
                        let wgt = wr * wc;
                        let p = tone(&line[i]);
                        for ch in 0..3 {
                            sums[cell][ch] += wgt * p[ch] as f64;
                        }
                        weights[cell] += wgt;
                    }
                }
            }
        }
        (sums, weights)
    }

    /// Cell integrals with pitch: panorama pixels split into parts, each part's
    /// solid angle given to the cell its centre falls in.
    fn integrate_rotated(
        &self,
        fov: f64,
        yaw: f64,
        pitch: f64,
        tone: &dyn Fn(&[f32; 3]) -> [f32; 3],
    ) -> (Vec<[f64; 3]>, Vec<f64>) {
        let (w, h) = (self.width as f64, self.height as f64);
        let cell_deg = (fov / LIGHT_COLS as f64).min(fov / 2.0 / LIGHT_ROWS as f64);
        let pixel_deg = (360.0 / w).max(180.0 / h);
        let split = ((4.0 * pixel_deg / cell_deg).ceil() as usize).clamp(1, 64);
        let (yaw, pitch) = (yaw.to_radians(), pitch.to_radians());
        let half_w = fov.to_radians() / 2.0;
        let half_h = half_w / 2.0;
        let n = LIGHT_ROWS * LIGHT_COLS;
        let mut sums = vec![[0f64; 3]; n];
        let mut weights = vec![0f64; n];
        let dlon = 2.0 * PI / (w * split as f64);
        let dlat = PI / (h * split as f64);
        // The sines and cosines of every part's longitude, computed once.
        let lons: Vec<(f64, f64)> = (0..self.width * split)
            .map(|k| (-PI + (k as f64 + 0.5) * dlon).sin_cos())
            .collect();
        // Directions farther from straight ahead than the window's corners cannot land
        // in it (for windows up to a hemisphere wide, whose corners are the farthest).
        let (ahead_lon, ahead_lat) = rotate(0.0, 0.0, yaw, pitch);
        let ahead = to_vector(ahead_lon, ahead_lat);
        let nearest = if fov <= 180.0 {
            half_w.cos() * half_h.cos() - 1e-9
        } else {
            -2.0
        };
        for j in 0..self.height {
            let row = &self.rgb[j * self.width..(j + 1) * self.width];
            for sj in 0..split {
                let top = PI / 2.0 - (j * split + sj) as f64 * dlat;
                let (sin_lat, cos_lat) = (top - dlat / 2.0).sin_cos();
                let solid = (top.sin() - (top - dlat).sin()) * dlon;
                for (i, pixel) in row.iter().enumerate() {
                    let mut toned = None;
                    for &(sin_lon, cos_lon) in &lons[i * split..(i + 1) * split] {
                        let v = [cos_lat * sin_lon, sin_lat, cos_lat * cos_lon];
                        if v[0] * ahead[0] + v[1] * ahead[1] + v[2] * ahead[2] < nearest {
                            continue;
                        }
                        let (vlon, vlat) = to_angles(unrotate(v, yaw, pitch));
                        if vlon.abs() >= half_w || vlat.abs() >= half_h {
                            continue;
                        }
                        let c = (((vlon + half_w) / (2.0 * half_w)) * LIGHT_COLS as f64) as usize;
                        let r = (((half_h - vlat) / (2.0 * half_h)) * LIGHT_ROWS as f64) as usize;
                        let cell = r.min(LIGHT_ROWS - 1) * LIGHT_COLS + c.min(LIGHT_COLS - 1);
                        let p = toned.get_or_insert_with(|| tone(pixel));
                        for ch in 0..3 {
                            sums[cell][ch] += solid * p[ch] as f64;
                        }
                        weights[cell] += solid;
                    }
                }
            }
        }
        (sums, weights)
    }
}

/// The viewer-frame direction (radians) of a cell's centre.
fn cell_centre(fov: f64, r: usize, c: usize) -> (f64, f64) {
    let lon = ((c as f64 + 0.5) / LIGHT_COLS as f64 - 0.5) * fov;
    let lat = (0.5 - (r as f64 + 0.5) / LIGHT_ROWS as f64) * fov / 2.0;
    (lon.to_radians(), lat.to_radians())
}

fn to_vector(lon: f64, lat: f64) -> [f64; 3] {
    // x right, y up, z ahead.
    [lat.cos() * lon.sin(), lat.sin(), lat.cos() * lon.cos()]
}

fn to_angles(v: [f64; 3]) -> (f64, f64) {
    (v[0].atan2(v[2]), v[1].clamp(-1.0, 1.0).asin())
}

/// A viewer-frame direction in the world: tilted up by `pitch`, then turned right by `yaw`.
fn rotate(lon: f64, lat: f64, yaw: f64, pitch: f64) -> (f64, f64) {
    let [x, y, z] = to_vector(lon, lat);
    let (y, z) = (
        y * pitch.cos() + z * pitch.sin(),
        -y * pitch.sin() + z * pitch.cos(),
    );
    let (x, z) = (
        x * yaw.cos() + z * yaw.sin(),
        -x * yaw.sin() + z * yaw.cos(),
    );
    to_angles([x, y, z])
}

/// The inverse of [`rotate`]: a world direction vector in the viewer's frame.
fn unrotate([x, y, z]: [f64; 3], yaw: f64, pitch: f64) -> [f64; 3] {
    let (x, z) = (x * yaw.cos() - z * yaw.sin(), x * yaw.sin() + z * yaw.cos());
    let (y, z) = (
        y * pitch.cos() - z * pitch.sin(),
        y * pitch.sin() + z * pitch.cos(),
    );
    [x, y, z]
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: usize = LIGHT_ROWS * LIGHT_COLS;

    /// A dark panorama with one bright pixel in the direction (`lon`, `lat`) degrees.
    fn spot(w: usize, lon: f64, lat: f64) -> Panorama {
        let h = w / 2;
        let mut rgb = vec![[0.0f32; 3]; w * h];
        let x = (((lon / 360.0 + 0.5) * w as f64) as usize).min(w - 1);
        let y = (((0.5 - lat / 180.0) * h as f64) as usize).min(h - 1);
        rgb[y * w + x] = [1.0, 0.5, 0.25];
        Panorama::from_linear(w, h, rgb).unwrap()
    }

    fn brightest(light: &Light) -> (usize, usize) {
        let cell = (0..N)
            .max_by(|&a, &b| light.0[a].total_cmp(&light.0[b]))
            .unwrap();
        (cell / LIGHT_COLS, cell % LIGHT_COLS)
    }

    fn lit_cells(light: &Light) -> usize {
        (0..N).filter(|&i| light.0[i] > 0.0).count()
    }

    #[test]
    fn a_uniform_map_gives_a_uniform_grid_at_any_view() {
        let pano = Panorama::from_linear(64, 32, vec![[0.2, 0.4, 0.8]; 64 * 32]).unwrap();
        for view in [
            View::default(),
            View {
                yaw: 33.0,
                fov: 90.0,
                ..View::default()
            },
            View {
                pitch: 20.0,
                yaw: -70.0,
                ..View::default()
            },
            View {
                fov: 360.0,
                ..View::default()
            },
        ] {
            let l = pano.light(&view);
            for (ch, want) in [0.2f32, 0.4, 0.8].into_iter().enumerate() {
                assert!(
                    l.0[ch * N..(ch + 1) * N]
                        .iter()
                        .all(|v| (v - want).abs() < 1e-5),
                    "{view:?}"
                );
            }
        }
    }

    #[test]
    fn a_bright_direction_lands_on_its_cell_and_yaw_moves_it() {
        // 360 px around: a pixel of 1 degree. With a 180-degree view a cell is 5.625 degrees.
        // Straight ahead, 20 degrees up: columns 15|16 meet at 0, so take 2.8 to the right.
        let pano = spot(360, 2.8, 20.0);
        let l = pano.light(&View::default());
        // Column 16 spans 0..5.625 degrees; row 4 spans 22.5..16.875 degrees up.
        assert_eq!(brightest(&l), (4, 16));
        assert_eq!(
            lit_cells(&l),
            1,
            "one pixel inside one cell lights only that cell"
        );
        // The colour is kept, and the cell's value is its mean over the cell's solid angle.
        assert!((l.0[N + 4 * LIGHT_COLS + 16] / l.0[4 * LIGHT_COLS + 16] - 0.5).abs() < 1e-5);
        let pixel = (20f64.to_radians().sin() - 19f64.to_radians().sin()) * 1.0;
        let cell = (22.5f64.to_radians().sin() - 16.875f64.to_radians().sin()) * 5.625;
        let want = (pixel / cell) as f32;
        assert!(
            (l.0[4 * LIGHT_COLS + 16] - want).abs() < 1e-5 * want.max(1.0),
            "{want}"
        );
        // Turning right by 90 degrees puts it 90 degrees to the viewer's left: 16 cells left.
        let turned = pano.light(&View {
            yaw: 90.0,
            ..View::default()
        });
        assert_eq!(brightest(&turned), (4, 0));
        // Turning left by 80 degrees puts it 82.8 degrees to the viewer's right.
        let turned = pano.light(&View {
            yaw: -80.0,
            ..View::default()
        });
        assert_eq!(brightest(&turned), (4, 30));
        // Behind the viewer it is not on the screen at all.
        assert_eq!(
            lit_cells(&pano.light(&View {
                yaw: 180.0,
                ..View::default()
            })),
            0
        );
    }

    #[test]
    fn pitch_tilts_the_view_and_agrees_with_the_exact_integral_when_level() {
        let pano = spot(360, 2.8, 20.0);
        // Tilting up by 20 degrees brings the spot to the middle rows (7|8 meet at 0).
        let tilted = pano.light(&View {
            pitch: 20.0,
            ..View::default()
        });
        let (r, c) = brightest(&tilted);
        assert!((7..=8).contains(&r) && c == 16, "{r}, {c}");
        // A tiny pitch takes the split-pixel path: it matches the exact one closely.
        let mut rgb = vec![[0.0f32; 3]; 360 * 180];
        for (i, p) in rgb.iter_mut().enumerate() {
            let (x, y) = (i % 360, i / 360);
            *p = [
                ((x * 7 + y * 3) % 17) as f32 / 17.0,
                (y as f32 / 180.0),
                0.3,
            ];
        }
        let pano = Panorama::from_linear(360, 180, rgb).unwrap();
        let exact = pano.light(&View {
            yaw: 12.0,
            ..View::default()
        });
        let split = pano.light(&View {
            yaw: 12.0,
            pitch: 1e-9,
            ..View::default()
        });
        assert!(exact.distance(&split) < 0.01, "{}", exact.distance(&split));
    }

    #[test]
    fn exposure_scales_before_the_monitor_clips() {
        let mut rgb = vec![[0.25f32; 3]; 64 * 32];
        rgb[0] = [50.0; 3];
        let pano = Panorama::from_linear(64, 32, rgb).unwrap();
        let l = pano.light(&View {
            exposure: 1.0,
            fov: 90.0,
            ..View::default()
        });
        assert!(l.0.iter().all(|v| (v - 0.5).abs() < 1e-5));
        let l = pano.light(&View {
            exposure: 3.0,
            fov: 90.0,
            ..View::default()
        });
        assert!(
            l.0.iter().all(|v| (v - 1.0).abs() < 1e-5),
            "clipped to white"
        );
    }

    fn temp_path(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("lsyd-pano-{}-{name}", std::process::id()))
    }

    #[test]
    fn hdr_and_exr_files_read_as_linear_light() {
        let (w, h) = (64u32, 32u32);
        let mut img = image::Rgb32FImage::from_pixel(w, h, image::Rgb([0.1, 0.2, 0.4]));
        img.put_pixel(0, 16, image::Rgb([4.0, 4.0, 4.0]));
        for (ext, format) in [
            ("hdr", image::ImageFormat::Hdr),
            ("exr", image::ImageFormat::OpenExr),
        ] {
            let path = temp_path(&format!("map.{ext}"));
            img.save_with_format(&path, format).unwrap();
            assert!(is_hdr_path(&path));
            let pano = Panorama::open(&path).unwrap();
            std::fs::remove_file(&path).ok();
            let l = pano.light(&View::default());
            // Radiance HDR keeps 8-bit mantissas: 1% tolerance.
            for (ch, want) in [0.1f32, 0.2, 0.4].into_iter().enumerate() {
                assert!(
                    l.0[ch * N..(ch + 1) * N]
                        .iter()
                        .all(|v| (v - want).abs() < want * 0.01),
                    "{ext}"
                );
            }
            // The bright pixel, behind the viewer and just below the horizon, fills
            // exactly cell (8, 16) when the viewer turns round.
            let behind = pano.light(&View {
                yaw: 180.0,
                exposure: -2.0,
                ..View::default()
            });
            let cell = 8 * LIGHT_COLS + 16;
            assert!(
                (behind.0[cell] - 1.0).abs() < 0.01,
                "{ext}: {}",
                behind.0[cell]
            );
            assert!((behind.0[cell - 1] - 0.025).abs() < 0.001, "{ext}");
        }
    }

    #[test]
    fn bad_maps_are_refused_with_what_is_wrong() {
        let path = temp_path("square.png");
        image::RgbImage::new(16, 16).save(&path).unwrap();
        let e = Panorama::open(&path).unwrap_err();
        std::fs::remove_file(&path).ok();
        assert!(e.contains("twice as wide as high"), "{e}");
        let e = Panorama::open(Path::new("/nonexistent/map.exr")).unwrap_err();
        assert!(
            e.contains("cannot open environment map /nonexistent/map.exr"),
            "{e}"
        );
        assert!(Panorama::from_linear(4, 2, vec![[f32::NAN; 3]; 8]).is_err());
    }
}
