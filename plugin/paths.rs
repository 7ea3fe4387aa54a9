//! Where the element finds its defaults: the ONNX Runtime library, the
//! shipped model and target lights.
//!
//! An installed plugin looks in a folder `lsydrelight/` next to its own file
//! (`<plugin dir>/lsydrelight/libonnxruntime.so`, `.../models/starter`,
//! `.../targets`); a plugin built in a checkout looks in the checkout that holds
//! it (`target/onnxruntime/libonnxruntime.so`, made by `scripts/setup.sh`, and
//! `models/`), found from the plugin's file or, when it is linked into a program
//! (tests, examples), from the program's. No path of the build machine is
//! compiled in. `LSYDRELIGHT_ORT_LIBRARY` overrides the library's path.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

static PLUGIN_FILE: OnceLock<Option<PathBuf>> = OnceLock::new();

/// Records the plugin's file, as GStreamer reports it when it loads the plugin.
pub fn set_plugin_file(file: Option<PathBuf>) {
    let _ = PLUGIN_FILE.set(file);
}

/// The file the plugin's code was loaded from: the plugin, or the program it is linked into.
fn own_file() -> Option<PathBuf> {
    PLUGIN_FILE
        .get()
        .cloned()
        .flatten()
        .or_else(|| std::env::current_exe().ok())
}

/// The checkout holding the plugin's file (`<checkout>/target/<profile>/...`):
/// the nearest folder above it with the shipped model. Else the current folder.
fn checkout() -> PathBuf {
    let is_checkout = |d: &Path| d.join("models/default/model.json").is_file();
    own_file()
        .and_then(|f| {
            f.ancestors()
                .skip(1)
                .find(|d| is_checkout(d))
                .map(Path::to_path_buf)
        })
        .or_else(|| std::env::current_dir().ok())
        .unwrap_or_default()
}

/// `<plugin dir>/lsydrelight`, for an installed plugin.
fn installed() -> Option<PathBuf> {
    let file = PLUGIN_FILE.get()?.as_ref()?;
    let dir = file.parent()?.join("lsydrelight");
    dir.is_dir().then_some(dir)
}

/// The first of the installed and the checkout location that exists, else the checkout's.
fn locate(installed_rel: &str, checkout_rel: &str) -> PathBuf {
    installed()
        .map(|d| d.join(installed_rel))
        .filter(|p| p.exists())
        .unwrap_or_else(|| checkout().join(checkout_rel))
}

pub fn default_ort_library() -> PathBuf {
    if let Some(p) = std::env::var_os("LSYDRELIGHT_ORT_LIBRARY") {
        return PathBuf::from(p);
    }
    locate("libonnxruntime.so", "target/onnxruntime/libonnxruntime.so")
}

/// The starter model, trained on many simulated people: the default until the
/// user trains their own (`lsydrelight train`).
pub fn default_model() -> PathBuf {
    locate("models/starter", "models/starter")
}

pub fn default_face_detector() -> PathBuf {
    locate("models/face/blazeface.onnx", "models/face/blazeface.onnx")
}

pub fn default_target() -> PathBuf {
    locate("targets/studio.png", "models/targets/studio.png")
}
