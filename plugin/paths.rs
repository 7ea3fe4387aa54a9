//! Where the element finds its defaults: the ONNX Runtime library, the
//! shipped model and target lights.
//!
//! An installed plugin looks in a folder `lsydrelight/` next to its own file
//! (`<plugin dir>/lsydrelight/libonnxruntime.so`, `.../models/default`,
//! `.../targets`); a plugin built in a checkout looks in the checkout
//! (`target/onnxruntime/libonnxruntime.so`, made by `scripts/setup.sh`, and
//! `models/`). `LSYDRELIGHT_ORT_LIBRARY` overrides the library's path.

use std::path::PathBuf;
use std::sync::OnceLock;

static PLUGIN_FILE: OnceLock<Option<PathBuf>> = OnceLock::new();

/// Records the plugin's file, as GStreamer reports it when it loads the plugin.
pub fn set_plugin_file(file: Option<PathBuf>) {
    let _ = PLUGIN_FILE.set(file);
}

/// This checkout, where a development build finds its files.
fn checkout() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
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

pub fn default_model() -> PathBuf {
    locate("models/default", "models/default")
}

pub fn default_target() -> PathBuf {
    locate("targets/studio.png", "models/targets/studio.png")
}
