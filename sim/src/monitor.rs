//! The monitor as a light source: geometry, cells and their radiance.
//!
//! A monitor frame is an sRGB image as a screen capture would record it.
//! Its light is the frame decoded to linear light and box-averaged into a
//! grid of cells; row 0 is the top of the screen and column 0 its left edge
//! as the user sees it. Each cell is an area light.

use crate::math::Vec3;

/// An 8-bit sRGB image, row-major, 3 bytes per pixel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<u8>,
}

impl RgbImage {
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            data: vec![0; width * height * 3],
        }
    }

    pub fn pixel(&self, x: usize, y: usize) -> [u8; 3] {
        let i = (y * self.width + x) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }
}

/// sRGB-encoded value in [0, 1] to linear light.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light in [0, 1] to sRGB-encoded value.
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Decoding table for 8-bit sRGB.
pub fn srgb8_to_linear_table() -> [f32; 256] {
    std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0))
}

/// Radiance of each monitor cell in linear light, 1.0 being full white.
#[derive(Clone, Debug, PartialEq)]
pub struct CellLight {
    pub rows: usize,
    pub cols: usize,
    /// Row-major, top row first, screen-left column first.
    pub rgb: Vec<Vec3>,
}

impl CellLight {
    pub fn uniform(rows: usize, cols: usize, rgb: Vec3) -> Self {
        Self {
            rows,
            cols,
            rgb: vec![rgb; rows * cols],
        }
    }

    /// Box average of a frame in linear light. The frame size must be a
    /// multiple of the grid, as for every frame the simulator shows.
    pub fn from_frame(frame: &RgbImage, rows: usize, cols: usize) -> Self {
        assert!(
            frame.width.is_multiple_of(cols) && frame.height.is_multiple_of(rows),
            "monitor frame {}x{} is not a multiple of the {cols}x{rows} cell grid",
            frame.width,
            frame.height
        );
        let lut = srgb8_to_linear_table();
        let (bw, bh) = (frame.width / cols, frame.height / rows);
        let norm = 1.0 / (bw * bh) as f32;
        let mut rgb = Vec::with_capacity(rows * cols);
        for r in 0..rows {
            for c in 0..cols {
                let mut sum = Vec3::ZERO;
                for y in r * bh..(r + 1) * bh {
                    for x in c * bw..(c + 1) * bw {
                        let [pr, pg, pb] = frame.pixel(x, y);
                        sum += Vec3::new(lut[pr as usize], lut[pg as usize], lut[pb as usize]);
                    }
                }
                rgb.push(sum * norm);
            }
        }
        Self { rows, cols, rgb }
    }

    pub fn add(&self, o: &CellLight) -> CellLight {
        CellLight {
            rows: self.rows,
            cols: self.cols,
            rgb: self.rgb.iter().zip(&o.rgb).map(|(a, b)| *a + *b).collect(),
        }
    }

    pub fn mean(&self) -> Vec3 {
        let n = self.rgb.len() as f32;
        self.rgb.iter().fold(Vec3::ZERO, |s, v| s + *v) * (1.0 / n)
    }
}

/// Where the monitor is and how it is cut into cells.
#[derive(Clone, Debug, PartialEq)]
pub struct MonitorGeometry {
    /// Width and height of the screen in metres.
    pub width_m: f32,
    pub height_m: f32,
    /// The screen's top edge, in metres below the camera.
    pub top_y: f32,
    /// Distance of the screen plane from the camera along the view axis (usually 0).
    pub z: f32,
    pub rows: usize,
    pub cols: usize,
    /// Cells are grouped for shadow tests: each group shares one shadow map.
    pub group_rows: usize,
    pub group_cols: usize,
}

impl Default for MonitorGeometry {
    fn default() -> Self {
        // A 27" 16:9 screen with the webcam on its top edge.
        MonitorGeometry {
            width_m: 0.60,
            height_m: 0.3375,
            top_y: 0.012,
            z: 0.0,
            rows: 16,
            cols: 32,
            group_rows: 4,
            group_cols: 8,
        }
    }
}

impl MonitorGeometry {
    /// Centre of cell (row, col) in the camera frame. The screen faces the
    /// user, so its left column (as the user sees it) is at image right, +x.
    pub fn cell_centre(&self, row: usize, col: usize) -> Vec3 {
        let cw = self.width_m / self.cols as f32;
        let ch = self.height_m / self.rows as f32;
        Vec3::new(
            0.5 * self.width_m - (col as f32 + 0.5) * cw,
            self.top_y + (row as f32 + 0.5) * ch,
            self.z,
        )
    }

    pub fn cell_area(&self) -> f32 {
        self.width_m * self.height_m / (self.rows * self.cols) as f32
    }

    /// Shadow group of a cell.
    pub fn group_of(&self, row: usize, col: usize) -> usize {
        let gr = row * self.group_rows / self.rows;
        let gc = col * self.group_cols / self.cols;
        gr * self.group_cols + gc
    }

    pub fn groups(&self) -> usize {
        self.group_rows * self.group_cols
    }

    /// Centre of a shadow group.
    pub fn group_centre(&self, group: usize) -> Vec3 {
        let (gr, gc) = (group / self.group_cols, group % self.group_cols);
        let gw = self.width_m / self.group_cols as f32;
        let gh = self.height_m / self.group_rows as f32;
        Vec3::new(
            0.5 * self.width_m - (gc as f32 + 0.5) * gw,
            self.top_y + (gr as f32 + 0.5) * gh,
            self.z,
        )
    }

    /// Validates a configuration before rendering with it.
    pub fn check(&self) -> Result<(), String> {
        if self.rows < 16 || self.cols < 32 {
            return Err(format!(
                "the monitor needs at least 16x32 cells, got {}x{}",
                self.rows, self.cols
            ));
        }
        if !self.rows.is_multiple_of(self.group_rows) || !self.cols.is_multiple_of(self.group_cols)
        {
            return Err("shadow groups must divide the cell grid".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip() {
        for i in 0..=255u32 {
            let v = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5);
        }
    }

    #[test]
    fn screen_left_is_image_right() {
        let m = MonitorGeometry::default();
        assert!(m.cell_centre(0, 0).x > 0.0);
        assert!(m.cell_centre(0, m.cols - 1).x < 0.0);
        assert!(m.cell_centre(m.rows - 1, 0).y > m.cell_centre(0, 0).y);
    }

    #[test]
    fn box_average_of_uniform_frame() {
        let mut f = RgbImage::new(64, 32);
        f.data.fill(255);
        let l = CellLight::from_frame(&f, 16, 32);
        assert!(l.rgb.iter().all(|v| (v.x - 1.0).abs() < 1e-6));
    }
}
