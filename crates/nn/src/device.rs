//! Where tensors live, chosen at run time by name: `cpu` (burn's pure-Rust `flex` backend, the
//! default, with our own convolution kernels) or, in the GPU build (`--features vulkan`), `vulkan`
//! (the best Vulkan adapter), `vulkan:N` (discrete GPU N) or `vulkan:cpu` (a Vulkan driver that runs
//! on the CPU, such as Mesa's lavapipe: how the GPU code path is tested on machines without a GPU).
//! `cuda` (burn's CUDA backend, whose build downloads LLVM) and `torch` (libtorch) were removed:
//! asking for them is an error that says what to use instead (`docs/backends.md`).
//!
//! ```
//! let cpu = equiarm_nn::device::parse("cpu").unwrap();
//! assert_eq!(cpu, equiarm_nn::device::cpu());
//! assert!(equiarm_nn::device::parse("tpu").is_err());
//! ```
//!
//! The device is an execution choice, not part of a run's config: weights and optimiser state
//! saved on one device load on another.
//!
//! Limitations: [`parse`] does not open the device; [`open`] and [`check`] do (one tiny
//! operation), so a missing GPU or driver is reported before a run starts rather than as a panic
//! inside it. The GPU build compiles its kernels at run time (WGSL, then SPIR-V through naga): the
//! first steps on a device are slow. Results on a GPU are not bit-identical to the CPU's, and GPU
//! runs are not promised to be bitwise repeatable.

use burn::tensor::{Device, Tensor};
use thiserror::Error;

/// The device names [`parse`] accepts, for help texts and errors.
pub const CHOICES: &str = "`cpu` (the default), or in the GPU build `vulkan`, `vulkan:N` (discrete GPU N) or `vulkan:cpu` (a CPU Vulkan driver)";

/// The command that builds the GPU build (the `vulkan` feature), for messages.
pub const GPU_BUILD: &str = "cargo build --release --features vulkan";

/// A device name that cannot be used.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum DeviceError {
    /// Not a device name this program knows.
    #[error("unknown device `{name}`: choose {CHOICES}")]
    Unknown {
        /// The name given.
        name: String,
    },
    /// `vulkan:` followed by something that is neither a device index nor `cpu`.
    #[error("device `{name}`: after `vulkan:` give a non-negative integer (`vulkan:0`) or `cpu` (`vulkan:cpu`)")]
    BadIndex {
        /// The name given.
        name: String,
    },
    /// A Vulkan device was asked of a binary built without the `vulkan` feature.
    #[error(
        "device `{name}`: this binary was built without the GPU build's `vulkan` feature: rebuild with `{GPU_BUILD}`"
    )]
    NoVulkan {
        /// The name given.
        name: String,
    },
    /// The CUDA device, which equiarm no longer has.
    #[error(
        "device `{name}`: equiarm has no CUDA backend (burn's CUDA build downloads LLVM, so it cannot build offline): build the GPU build with `{GPU_BUILD}` and use `--device vulkan`, which runs on NVIDIA GPUs through their Vulkan driver (docs/backends.md)"
    )]
    CudaRemoved {
        /// The name given.
        name: String,
    },
    /// The libtorch CPU device, which equiarm no longer has.
    #[error(
        "device `{name}`: equiarm no longer has a libtorch backend: use `cpu` (the default), whose own convolution kernels run an SAC update faster than libtorch did (docs/backends.md)"
    )]
    TorchRemoved {
        /// The name given.
        name: String,
    },
    /// The device is not there or could not run a tiny operation (no GPU, no driver, index out
    /// of range).
    #[error("device `{device}` is not usable: {message}")]
    Unusable {
        /// The device: its name, or as burn prints it.
        device: String,
        /// What failed.
        message: String,
    },
}

/// The CPU device: burn's `flex` backend (pure Rust, multi-threaded, SIMD). The default.
pub fn cpu() -> Device {
    Device::flex()
}

/// True when this binary is the GPU build (the `vulkan` feature).
pub const fn vulkan_enabled() -> bool {
    cfg!(feature = "vulkan")
}

/// The device named `name` (case-insensitive, surrounding blanks ignored): `cpu` (also `flex`,
/// burn's name for it), or in the GPU build `vulkan` (the adapter wgpu prefers), `vulkan:N`
/// (discrete GPU N) or `vulkan:cpu` (a CPU adapter, e.g. lavapipe). Returns the plain
/// (non-autodiff) device; callers add autodiff where they train. `cuda[:N]` and `torch` are refused
/// with [`DeviceError::CudaRemoved`] and [`DeviceError::TorchRemoved`].
pub fn parse(name: &str) -> Result<Device, DeviceError> {
    let given = || name.to_string();
    match choice(name)? {
        Choice::Cpu => Ok(cpu()),
        Choice::Vulkan(adapter) => vulkan(adapter).ok_or_else(|| DeviceError::NoVulkan { name: given() }),
        Choice::Cuda => Err(DeviceError::CudaRemoved { name: given() }),
        Choice::Torch => Err(DeviceError::TorchRemoved { name: given() }),
    }
}

/// Which Vulkan adapter a name asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Adapter {
    /// The one wgpu prefers (a high-power GPU first).
    Default,
    /// Discrete GPU N.
    Discrete(usize),
    /// A driver that runs on the CPU (lavapipe).
    Cpu,
}

/// A device name, understood.
enum Choice {
    Cpu,
    Vulkan(Adapter),
    Cuda,
    Torch,
}

fn choice(name: &str) -> Result<Choice, DeviceError> {
    let given = || name.to_string();
    let lower = name.trim().to_ascii_lowercase();
    match lower.as_str() {
        "cpu" | "flex" => Ok(Choice::Cpu),
        "vulkan" => Ok(Choice::Vulkan(Adapter::Default)),
        "vulkan:cpu" => Ok(Choice::Vulkan(Adapter::Cpu)),
        "torch" | "libtorch" => Ok(Choice::Torch),
        "cuda" => Ok(Choice::Cuda),
        other if other.starts_with("cuda:") => Ok(Choice::Cuda),
        other => match other.strip_prefix("vulkan:") {
            Some(n) if !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) => n
                .parse()
                .map(|i| Choice::Vulkan(Adapter::Discrete(i)))
                .map_err(|_| DeviceError::BadIndex { name: given() }),
            Some(_) => Err(DeviceError::BadIndex { name: given() }),
            None => Err(DeviceError::Unknown { name: given() }),
        },
    }
}

#[cfg(feature = "vulkan")]
fn vulkan(adapter: Adapter) -> Option<Device> {
    use burn::backend::{WgpuBackend, WgpuDevice, WgpuDeviceKind};
    let kind = match adapter {
        Adapter::Default => WgpuDeviceKind::DefaultDevice,
        Adapter::Discrete(i) => WgpuDeviceKind::DiscreteGpu(i),
        Adapter::Cpu => WgpuDeviceKind::Cpu,
    };
    // Pinned to Vulkan: the device comes up there or not at all (not on OpenGL instead).
    Some(Device::new(WgpuDevice::new(kind).on(WgpuBackend::Vulkan)))
}

#[cfg(not(feature = "vulkan"))]
fn vulkan(_adapter: Adapter) -> Option<Device> {
    None
}

/// Whether wgpu finds any adapter at all (no Vulkan loader or no driver: none). Asking does not
/// panic, unlike opening a device that is not there.
#[cfg(feature = "vulkan")]
fn any_adapter() -> bool {
    !Device::enumerate(burn::tensor::DeviceType::Wgpu).into_vec().is_empty()
}

#[cfg(not(feature = "vulkan"))]
fn any_adapter() -> bool {
    false
}

/// What `device` is, in words, for logs and reports: on a Vulkan device the adapter's own name and
/// what its kernels are compiled for (opens the device), else burn's name for it.
pub fn describe(device: &Device) -> String {
    #[cfg(feature = "vulkan")]
    if device.clone().without_autodiff() != cpu()
        && let Some(id) = device.identity()
    {
        return format!("{} ({}; {device:?})", id.name, id.fingerprint);
    }
    format!("{device:?}")
}

/// Open `device` and run one tiny operation on it, so that a missing GPU or driver becomes an
/// error here rather than a panic in the middle of building a network. Cheap on the CPU.
pub fn check(device: &Device) -> Result<(), DeviceError> {
    let unusable = |message: String| DeviceError::Unusable { device: format!("{device:?}"), message };
    // NOTE: a backend that cannot open its device panics (burn's device API has no fallible
    // constructor); the panic is caught and turned into an error. Its message is also printed
    // by the panic hook.
    let run = std::panic::AssertUnwindSafe(|| {
        let t = Tensor::<1>::from_floats([1.0, 2.0], &device.clone().without_autodiff());
        t.sum().try_into_data().map(|d| d.try_to_vec::<f32>().map(|v| v.first().copied()))
    });
    match std::panic::catch_unwind(run) {
        Ok(Ok(Ok(Some(3.0)))) => Ok(()),
        Ok(Ok(other)) => Err(unusable(format!("1 + 2 gave {other:?}"))),
        Ok(Err(e)) => Err(unusable(format!("{e:?}"))),
        Err(panic) => {
            let message = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "the backend panicked".into());
            Err(unusable(message))
        }
    }
}

/// [`parse`], then (for a Vulkan device) ask whether wgpu finds any adapter, then [`check`]: the
/// device named `name`, known to work.
pub fn open(name: &str) -> Result<Device, DeviceError> {
    let device = parse(name)?;
    if let Choice::Vulkan(_) = choice(name)?
        && !any_adapter()
    {
        let message = "no Vulkan adapter found: no Vulkan loader (libvulkan.so.1) or no driver (an NVIDIA driver with its Vulkan ICD, or Mesa's lavapipe for `vulkan:cpu`); `vulkaninfo --summary` lists what this machine has".to_string();
        return Err(DeviceError::Unusable { device: name.trim().to_string(), message });
    }
    check(&device).map_err(|e| match e {
        DeviceError::Unusable { message, .. } => DeviceError::Unusable { device: name.trim().to_string(), message },
        e => e,
    })?;
    Ok(device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_is_flex_and_the_default_spellings_parse() {
        for name in ["cpu", "CPU", " cpu ", "flex"] {
            let d = parse(name).unwrap();
            assert_eq!(d, Device::flex(), "{name}");
            assert!(!d.is_autodiff());
        }
        check(&cpu()).unwrap();
        check(&cpu().autodiff()).unwrap();
        assert_eq!(open("cpu").unwrap(), Device::flex());
    }

    #[test]
    fn opening_a_vulkan_device_never_panics() {
        // Without the feature: the rebuild hint. With it: the device, or an error saying it is not
        // there (this machine may have no GPU or no Vulkan driver).
        for name in ["vulkan", "vulkan:7", "vulkan:cpu"] {
            match open(name) {
                Ok(d) => assert!(vulkan_enabled() && d == parse(name).unwrap()),
                Err(DeviceError::NoVulkan { .. }) => assert!(!vulkan_enabled()),
                Err(e @ DeviceError::Unusable { .. }) => {
                    assert!(vulkan_enabled() && e.to_string().contains(name), "{e}")
                }
                Err(e) => panic!("{name}: {e}"),
            }
        }
    }

    #[test]
    fn the_removed_torch_device_is_refused_with_the_reason() {
        for name in ["torch", "TORCH", " libtorch "] {
            let e = open(name).unwrap_err();
            assert_eq!(e, DeviceError::TorchRemoved { name: name.into() });
            assert!(e.to_string().contains("no longer has a libtorch backend: use `cpu`"), "{e}");
        }
    }

    #[test]
    fn the_removed_cuda_device_points_to_the_gpu_build() {
        for name in ["cuda", "CUDA", "cuda:0", "cuda:3", "cuda:x"] {
            let e = open(name).unwrap_err();
            assert_eq!(e, DeviceError::CudaRemoved { name: name.into() });
            let text = e.to_string();
            assert!(text.contains(GPU_BUILD) && text.contains("--device vulkan"), "{text}");
        }
    }

    #[test]
    fn unknown_names_list_the_choices() {
        for name in ["", "gpu", "tpu", "cudaa", "cpu:0", "wgpu", "torch:0", "vulkan0", "vk"] {
            let e = parse(name).unwrap_err();
            assert_eq!(e, DeviceError::Unknown { name: name.into() });
            let text = e.to_string();
            assert!(text.contains("`cpu`") && text.contains("`vulkan:N`"), "{text}");
        }
    }

    #[test]
    fn bad_vulkan_indices_are_errors() {
        for name in [
            "vulkan:",
            "vulkan:-1",
            "vulkan:x",
            "vulkan:1.5",
            "vulkan:+1",
            "vulkan:99999999999999999999999",
            "vulkan:gpu",
        ] {
            let e = parse(name).unwrap_err();
            assert_eq!(e, DeviceError::BadIndex { name: name.into() }, "{name}");
            assert!(e.to_string().contains("non-negative integer"), "{e}");
        }
    }

    #[test]
    fn the_no_vulkan_error_names_the_device_and_the_rebuild_command() {
        let e = DeviceError::NoVulkan { name: "vulkan:3".into() }.to_string();
        assert!(e.starts_with("device `vulkan:3`: "), "{e}");
        assert!(e.contains(&format!("rebuild with `{GPU_BUILD}`")), "{e}");
        assert!(GPU_BUILD.contains("--features vulkan"), "{GPU_BUILD}");
    }

    // The test command builds the GPU build, so this one runs in default-feature builds only.
    #[cfg(not(feature = "vulkan"))]
    #[test]
    fn vulkan_without_the_feature_names_the_rebuild_command() {
        assert!(!vulkan_enabled());
        for name in ["vulkan", "VULKAN", "vulkan:0", "vulkan:3", "vulkan:cpu"] {
            let e = parse(name).unwrap_err();
            assert_eq!(e, DeviceError::NoVulkan { name: name.into() });
            assert!(e.to_string().contains(&format!("rebuild with `{GPU_BUILD}`")), "{e}");
        }
    }

    #[cfg(feature = "vulkan")]
    #[test]
    fn vulkan_names_give_distinct_vulkan_devices() {
        assert!(vulkan_enabled());
        let names = ["vulkan", "vulkan:0", "vulkan:1", "vulkan:cpu"];
        let devices: Vec<Device> = names.iter().map(|n| parse(n).unwrap()).collect();
        assert_eq!(parse("VULKAN:0").unwrap(), devices[1]);
        for (i, a) in devices.iter().enumerate() {
            assert_ne!(*a, cpu());
            for b in &devices[i + 1..] {
                assert_ne!(a, b);
            }
        }
    }
}
