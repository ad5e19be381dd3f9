//! The library's error type: every variant prints as one line that names the problem.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(
        "Vulkan loader (libvulkan.so.1) not found: install it with `apt-get install libvulkan1 mesa-vulkan-drivers` ({0})"
    )]
    NoLoader(String),
    #[error(
        "no Vulkan device found: install a Vulkan driver, e.g. `apt-get install mesa-vulkan-drivers` for lavapipe (CPU)"
    )]
    NoDevice,
    #[error(
        "validation layers requested but VK_LAYER_KHRONOS_validation is not installed: `apt-get install vulkan-validationlayers`"
    )]
    NoValidationLayer,
    #[error("device override {wanted:?} matches no Vulkan device; available: {available}")]
    UnknownDevice { wanted: String, available: String },
    #[error("device {name:?} is unsuitable: {reason}")]
    UnsuitableDevice { name: String, reason: String },
    #[error("{who} needs the Vulkan feature {feature}, which {reason}")]
    MissingFeature {
        who: String,
        feature: &'static str,
        reason: String,
    },
    #[error("Vulkan call {call} failed: {result}")]
    Vulkan {
        call: &'static str,
        result: ash::vk::Result,
    },
    #[error("GPU memory allocation for {what} failed: {source}")]
    Allocation {
        what: String,
        #[source]
        source: gpu_allocator::AllocationError,
    },
    #[error("{path}: {message}")]
    Config { path: PathBuf, message: String },
    #[error("invalid {what}: {message}")]
    Invalid { what: String, message: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("timed out after {seconds} s waiting for the GPU ({what})")]
    Timeout { what: &'static str, seconds: f64 },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Invalid {
            what: what.into(),
            message: message.into(),
        }
    }
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// A TOML error in file `path` (whose text is `text`) as `path:line: message`.
    pub fn toml(path: &std::path::Path, text: &str, e: &toml::de::Error) -> Self {
        let line = e
            .span()
            .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
        let path = match line {
            Some(l) => PathBuf::from(format!("{}:{l}", path.display())),
            None => path.to_path_buf(),
        };
        Error::Config {
            path,
            message: e.message().trim().replace('\n', " "),
        }
    }
}

/// Turns a raw `vk::Result` into [`Error::Vulkan`] naming the call.
pub trait VkResultExt<T> {
    fn vk(self, call: &'static str) -> Result<T>;
}

impl<T> VkResultExt<T> for Result<T, ash::vk::Result> {
    fn vk(self, call: &'static str) -> Result<T> {
        self.map_err(|result| Error::Vulkan { call, result })
    }
}
