//! `--target`: what the face is relit to. A preset's name, a PNG of monitor
//! content, an environment map (Radiance .hdr or OpenEXR .exr, or a PNG/JPEG
//! panorama when --fov, --yaw, --pitch or --exposure is given), or a video
//! (its frames are the target as they play, aligned with the face's).

use std::path::{Path, PathBuf};

use gst::prelude::*;
use gstlsydrelight::targets::{Preset, panorama};

use super::folder::RECORDING_EXTENSIONS;
use crate::exit::Failure;

#[derive(Clone, Debug, PartialEq)]
pub enum Target {
    Preset(Preset),
    Image(PathBuf),
    Environment(PathBuf, panorama::View),
    Video(PathBuf),
}

/// How an environment map is seen, as the command line gave it.
#[derive(Clone, Copy, Debug, Default)]
pub struct ViewArgs {
    pub fov: Option<f64>,
    pub yaw: Option<f64>,
    pub pitch: Option<f64>,
    pub exposure: Option<f64>,
}

impl ViewArgs {
    fn given(&self) -> bool {
        self.fov.is_some() || self.yaw.is_some() || self.pitch.is_some() || self.exposure.is_some()
    }

    fn view(&self) -> panorama::View {
        let d = panorama::View::default();
        panorama::View {
            fov: self.fov.unwrap_or(d.fov),
            yaw: self.yaw.unwrap_or(d.yaw),
            pitch: self.pitch.unwrap_or(d.pitch),
            exposure: self.exposure.unwrap_or(d.exposure),
        }
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn presets() -> String {
    Preset::ALL.map(|p| p.nick()).join(", ")
}

impl Target {
    /// Reads `--target` and the view options; files are checked to exist.
    pub fn parse(value: &str, view: ViewArgs) -> Result<Target, Failure> {
        if let Some(preset) = Preset::from_nick(value) {
            return if view.given() {
                Err(Failure::usage(format!(
                    "--fov, --yaw, --pitch and --exposure are for environment maps; --target {value} is a preset"
                )))
            } else {
                Ok(Target::Preset(preset))
            };
        }
        let path = PathBuf::from(value);
        if !path.is_file() {
            return Err(Failure::new(format!(
                "--target {value}: no such file, and not a preset (presets: {})",
                presets()
            )));
        }
        let ext = extension(&path);
        if panorama::is_hdr_path(&path)
            || (view.given() && ["png", "jpg", "jpeg"].contains(&ext.as_str()))
        {
            // Read now, so a bad map fails before any recording is opened.
            panorama::Panorama::open(&path).map_err(|e| Failure::new(format!("--target {e}")))?;
            return Ok(Target::Environment(path, view.view()));
        }
        if view.given() {
            return Err(Failure::usage(format!(
                "--fov, --yaw, --pitch and --exposure are for environment maps (.hdr, .exr, or a PNG/JPEG panorama); --target {value} is not one"
            )));
        }
        if RECORDING_EXTENSIONS.contains(&ext.as_str()) {
            return Ok(Target::Video(path));
        }
        check_png(&path)?;
        Ok(Target::Image(path))
    }

    /// Sets the element's target properties.
    pub fn apply(&self, relight: &gst::Element) -> Result<(), Failure> {
        let utf8 = |p: &Path| {
            p.to_str()
                .map(str::to_owned)
                .ok_or_else(|| Failure::new(format!("{}: the path is not UTF-8", p.display())))
        };
        match self {
            Target::Preset(p) => relight.set_property("target-preset", *p),
            Target::Image(path) => relight.set_property("target-location", utf8(path)?),
            Target::Environment(path, view) => {
                relight.set_property("target-fov", view.fov);
                relight.set_property("target-yaw", view.yaw);
                relight.set_property("target-pitch", view.pitch);
                relight.set_property("target-exposure", view.exposure);
                relight.set_property("target-environment", utf8(path)?);
            }
            // The graph feeds the video into target_sink.
            Target::Video(_) => {}
        }
        Ok(())
    }
}

fn check_png(path: &Path) -> Result<(), Failure> {
    use std::io::Read;
    const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(SIGNATURE.len() as u64).read_to_end(&mut head))
        .map_err(|e| Failure::new(format!("--target {}: {e}", path.display())))?;
    if head != SIGNATURE {
        return Err(Failure::new(format!(
            "--target {}: not a PNG image; pass a PNG of monitor content (shipped ones are in \
             models/targets), an environment map (.hdr, .exr), a video, or a preset ({})",
            path.display(),
            presets()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_presets_and_refuses_view_options_for_what_is_not_a_map() {
        assert_eq!(
            Target::parse("candle", ViewArgs::default()).unwrap(),
            Target::Preset(Preset::Candle)
        );
        let yaw = ViewArgs {
            yaw: Some(90.0),
            ..ViewArgs::default()
        };
        let e = Target::parse("candle", yaw).unwrap_err();
        assert!(e.to_string().contains("are for environment maps"), "{e}");
        let e = Target::parse("/nonexistent/x.exr", ViewArgs::default()).unwrap_err();
        assert!(e.to_string().contains("neon"), "lists the presets: {e}");
    }
}
