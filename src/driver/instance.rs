//! Vulkan loader, instance and the validation-message gate.
//!
//! The instance enables no surface/WSI extension: vkterrain never presents. When validation is
//! requested, `VK_LAYER_KHRONOS_validation` runs with synchronization validation on, and every
//! warning or error it reports is counted in a [`ValidationLog`] so tests can fail on it.

use std::ffi::{CStr, c_char, c_void};
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use ash::vk;

use crate::error::{Error, Result, VkResultExt};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Messages from the validation layers: warnings and errors are counted and kept.
#[derive(Default)]
pub struct ValidationLog {
    count: AtomicU64,
    messages: Mutex<Vec<String>>,
}

impl ValidationLog {
    /// Number of validation warnings and errors reported so far.
    pub fn count(&self) -> u64 {
        self.count.load(Ordering::SeqCst)
    }

    /// The messages reported so far (at most the first 64 are kept).
    pub fn messages(&self) -> Vec<String> {
        self.messages.lock().map(|m| m.clone()).unwrap_or_default()
    }

    fn record(&self, message: String) {
        self.count.fetch_add(1, Ordering::SeqCst);
        if let Ok(mut m) = self.messages.lock()
            && m.len() < 64
        {
            m.push(message);
        }
    }
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    kind: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes valid callback data; `user` is the `ValidationLog` kept alive by
    // the `Instance` that owns the messenger.
    let (log, data) = unsafe { (&*(user as *const ValidationLog), &*data) };
    let message = if data.p_message.is_null() {
        String::from("(no message)")
    } else {
        unsafe { CStr::from_ptr(data.p_message) }
            .to_string_lossy()
            .into_owned()
    };
    let line = format!("[{severity:?} {kind:?}] {message}");
    tracing::error!(target: "vulkan_validation", "{line}");
    log.record(line);
    vk::FALSE
}

/// The loaded Vulkan library and an instance, with the validation messenger when enabled.
pub struct Instance {
    pub entry: ash::Entry,
    pub raw: ash::Instance,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    pub validation: Option<Arc<ValidationLog>>,
    pub api_version: u32,
}

impl Instance {
    pub fn new(validation: bool) -> Result<Self> {
        // SAFETY: dlopen of the system loader; no other Vulkan state exists yet.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| Error::NoLoader(e.to_string()))?;
        let api_version = instance_api_version(&entry)?;
        let (layers, extensions) = layers_and_extensions(&entry, validation)?;
        let log = Arc::new(ValidationLog::default());
        let mut messenger_info = validation_messenger_info(&log);
        let raw = create_instance(
            &entry,
            api_version,
            &layers,
            &extensions,
            validation.then_some(&mut messenger_info),
        )?;
        let debug = if validation {
            Some(create_messenger(&entry, &raw, &messenger_info)?)
        } else {
            None
        };
        Ok(Instance {
            entry,
            raw,
            debug,
            validation: validation.then_some(log),
            api_version,
        })
    }
}

/// The API version to ask for: the loader's, at most 1.3; an error below 1.2.
fn instance_api_version(entry: &ash::Entry) -> Result<u32> {
    let loader_version = unsafe { entry.try_enumerate_instance_version() }
        .vk("vkEnumerateInstanceVersion")?
        .unwrap_or(vk::API_VERSION_1_0);
    if loader_version < vk::API_VERSION_1_2 {
        return Err(Error::UnsuitableDevice {
            name: "Vulkan loader".into(),
            reason: format!(
                "instance version {}.{} < 1.2 (vkterrain needs timeline semaphores)",
                vk::api_version_major(loader_version),
                vk::api_version_minor(loader_version)
            ),
        });
    }
    Ok(loader_version.min(vk::API_VERSION_1_3))
}

/// The instance layers and extensions to enable: none without validation; with it, the
/// validation layer (an error if it is not installed) and its two extensions.
fn layers_and_extensions(
    entry: &ash::Entry,
    validation: bool,
) -> Result<(Vec<*const c_char>, Vec<*const c_char>)> {
    let mut layers = Vec::new();
    let mut extensions = Vec::new();
    if validation {
        let available = unsafe { entry.enumerate_instance_layer_properties() }
            .vk("vkEnumerateInstanceLayerProperties")?;
        if !available
            .iter()
            .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER))
        {
            return Err(Error::NoValidationLayer);
        }
        layers.push(VALIDATION_LAYER.as_ptr());
        extensions.push(ash::ext::debug_utils::NAME.as_ptr());
        extensions.push(ash::ext::validation_features::NAME.as_ptr());
    }
    Ok((layers, extensions))
}

/// The validation messenger's create info: warnings and errors of every type, reported to
/// [`debug_callback`] with `log` as its user data (`log` must outlive the messenger).
fn validation_messenger_info(
    log: &Arc<ValidationLog>,
) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
        .user_data(Arc::as_ptr(log) as *mut c_void)
}

/// `vkCreateInstance`; with `messenger_info` (validation on), synchronization validation is
/// enabled and the messenger chained in.
fn create_instance(
    entry: &ash::Entry,
    api_version: u32,
    layers: &[*const c_char],
    extensions: &[*const c_char],
    messenger_info: Option<&mut vk::DebugUtilsMessengerCreateInfoEXT<'static>>,
) -> Result<ash::Instance> {
    let app = vk::ApplicationInfo::default()
        .application_name(c"vkterrain")
        .engine_name(c"vkterrain")
        .api_version(api_version);
    let enables = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
    let mut features = vk::ValidationFeaturesEXT::default().enabled_validation_features(&enables);
    let mut info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(layers)
        .enabled_extension_names(extensions);
    let mut messenger_info = messenger_info;
    if let Some(messenger_info) = messenger_info.as_deref_mut() {
        // Chained so that instance creation and destruction are validated too.
        info = info.push_next(&mut features).push_next(messenger_info);
    }
    let created = unsafe { entry.create_instance(&info, None) };
    // Chaining pointed the messenger's create info at `features`, which ends here: it stands
    // alone again before `create_messenger` reads it.
    if let Some(messenger_info) = messenger_info {
        messenger_info.p_next = std::ptr::null();
    }
    created.map_err(|result| match result {
        vk::Result::ERROR_INCOMPATIBLE_DRIVER => Error::NoDevice,
        result => Error::Vulkan {
            call: "vkCreateInstance",
            result,
        },
    })
}

/// The validation messenger of `raw`; if it cannot be created, `raw` is destroyed.
fn create_messenger(
    entry: &ash::Entry,
    raw: &ash::Instance,
    messenger_info: &vk::DebugUtilsMessengerCreateInfoEXT<'static>,
) -> Result<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)> {
    let loader = ash::ext::debug_utils::Instance::new(entry, raw);
    match unsafe { loader.create_debug_utils_messenger(messenger_info, None) } {
        Ok(m) => Ok((loader, m)),
        Err(result) => {
            unsafe { raw.destroy_instance(None) };
            Err(Error::Vulkan {
                call: "vkCreateDebugUtilsMessengerEXT",
                result,
            })
        }
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        unsafe {
            if let Some((loader, messenger)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(messenger, None);
            }
            self.raw.destroy_instance(None);
        }
    }
}
