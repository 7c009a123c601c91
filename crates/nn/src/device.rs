//! Where tensors live, chosen at run time by name: `cpu` (burn's pure-Rust `flex` backend, the
//! default, with our own convolution kernels) or `cuda` / `cuda:N` (an NVIDIA GPU through burn's
//! CubeCL CUDA backend; only in a binary built with the `cuda` feature). `torch` (libtorch through
//! burn's `tch` backend) was removed once `cpu` became faster than it: asking for it is an error
//! that says so (`docs/backends.md`).
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
//! inside it. CubeCL compiles its kernels at run time: the first steps on a GPU are slow. Results
//! on a GPU are not bit-identical to the CPU's, and GPU runs are not promised to be bitwise
//! repeatable. The CUDA path has not been run on a GPU yet.

use burn::tensor::{Device, Tensor};
use thiserror::Error;

/// The device names [`parse`] accepts, for help texts and errors.
pub const CHOICES: &str = "`cpu` (the default) or `cuda` / `cuda:N` (CUDA device N)";

/// A device name that cannot be used.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum DeviceError {
    /// Not a device name this program knows.
    #[error("unknown device `{name}`: choose {CHOICES}")]
    Unknown {
        /// The name given.
        name: String,
    },
    /// `cuda:` followed by something that is not a device index.
    #[error("device `{name}`: the CUDA device index must be a non-negative integer, e.g. `cuda:0`")]
    BadIndex {
        /// The name given.
        name: String,
    },
    /// A CUDA device was asked of a binary built without the `cuda` feature.
    #[error(
        "device `{name}`: this binary was built without the `cuda` feature: rebuild with `cargo build --release --features cuda`"
    )]
    NoCuda {
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

/// True when this binary was built with the `cuda` feature.
pub const fn cuda_enabled() -> bool {
    cfg!(feature = "cuda")
}

/// The device named `name` (case-insensitive, surrounding blanks ignored): `cpu` (also `flex`,
/// burn's name for it), `cuda` (device 0) or `cuda:N`. Returns the plain (non-autodiff) device;
/// callers add autodiff where they train. `torch` (or `libtorch`) is refused with
/// [`DeviceError::TorchRemoved`].
pub fn parse(name: &str) -> Result<Device, DeviceError> {
    match choice(name)? {
        Choice::Cpu => Ok(cpu()),
        Choice::Cuda(index) => cuda(index).ok_or_else(|| DeviceError::NoCuda { name: name.to_string() }),
        Choice::Torch => Err(DeviceError::TorchRemoved { name: name.to_string() }),
    }
}

/// A device name, understood.
enum Choice {
    Cpu,
    Cuda(usize),
    Torch,
}

fn choice(name: &str) -> Result<Choice, DeviceError> {
    let given = || name.to_string();
    let lower = name.trim().to_ascii_lowercase();
    match lower.as_str() {
        "cpu" | "flex" => Ok(Choice::Cpu),
        "cuda" => Ok(Choice::Cuda(0)),
        "torch" | "libtorch" => Ok(Choice::Torch),
        other => match other.strip_prefix("cuda:") {
            Some(n) if !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) => {
                n.parse().map(Choice::Cuda).map_err(|_| DeviceError::BadIndex { name: given() })
            }
            Some(_) => Err(DeviceError::BadIndex { name: given() }),
            None => Err(DeviceError::Unknown { name: given() }),
        },
    }
}

#[cfg(feature = "cuda")]
fn cuda(index: usize) -> Option<Device> {
    Some(Device::cuda(index))
}

#[cfg(not(feature = "cuda"))]
fn cuda(_index: usize) -> Option<Device> {
    None
}

/// The CUDA devices the driver reports (none without a driver); asking does not panic, unlike
/// opening a device that is not there.
#[cfg(feature = "cuda")]
fn cuda_devices() -> Vec<Device> {
    Device::enumerate(burn::tensor::DeviceType::Cuda).into_vec()
}

#[cfg(not(feature = "cuda"))]
fn cuda_devices() -> Vec<Device> {
    Vec::new()
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

/// [`parse`], then (for a CUDA device) ask the driver whether that device exists, then [`check`]:
/// the device named `name`, known to work.
pub fn open(name: &str) -> Result<Device, DeviceError> {
    let device = parse(name)?;
    if let Choice::Cuda(index) = choice(name)? {
        let found = cuda_devices();
        if !found.contains(&device) {
            let message = match found.len() {
                0 => "no CUDA device found (no NVIDIA driver, or no GPU visible to this process)".to_string(),
                n => format!("CUDA device {index} does not exist: this machine has {n} (cuda:0 to cuda:{})", n - 1),
            };
            return Err(DeviceError::Unusable { device: name.trim().to_string(), message });
        }
    }
    check(&device)?;
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
    fn opening_a_cuda_device_never_panics() {
        // Without the feature: the rebuild hint. With it: the device, or an error saying it is not
        // there (this machine may have no GPU or no driver).
        for name in ["cuda", "cuda:7"] {
            match open(name) {
                Ok(d) => assert!(cuda_enabled() && d == parse(name).unwrap()),
                Err(DeviceError::NoCuda { .. }) => assert!(!cuda_enabled()),
                Err(e @ DeviceError::Unusable { .. }) => assert!(cuda_enabled() && e.to_string().contains(name), "{e}"),
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
    fn unknown_names_list_the_choices() {
        for name in ["", "gpu", "tpu", "cudaa", "cpu:0", "wgpu", "torch:0"] {
            let e = parse(name).unwrap_err();
            assert_eq!(e, DeviceError::Unknown { name: name.into() });
            let text = e.to_string();
            assert!(text.contains("`cpu`") && text.contains("`cuda:N`"), "{text}");
        }
    }

    #[test]
    fn bad_cuda_indices_are_errors() {
        for name in ["cuda:", "cuda:-1", "cuda:x", "cuda:1.5", "cuda:+1", "cuda:99999999999999999999999"] {
            let e = parse(name).unwrap_err();
            assert_eq!(e, DeviceError::BadIndex { name: name.into() }, "{name}");
            assert!(e.to_string().contains("non-negative integer"), "{e}");
        }
    }

    #[cfg(not(feature = "cuda"))]
    #[test]
    fn cuda_without_the_feature_names_the_rebuild_command() {
        assert!(!cuda_enabled());
        for name in ["cuda", "CUDA", "cuda:0", "cuda:3"] {
            let e = parse(name).unwrap_err();
            assert_eq!(e, DeviceError::NoCuda { name: name.into() });
            assert!(
                e.to_string()
                    .contains("built without the `cuda` feature: rebuild with `cargo build --release --features cuda`"),
                "{e}"
            );
        }
    }

    #[cfg(feature = "cuda")]
    #[test]
    fn cuda_names_give_cuda_devices() {
        assert!(cuda_enabled());
        assert_eq!(parse("cuda").unwrap(), Device::cuda(0));
        assert_eq!(parse("cuda:0").unwrap(), Device::cuda(0));
        assert_eq!(parse("CUDA:2").unwrap(), Device::cuda(2));
        assert_ne!(parse("cuda:1").unwrap(), Device::cuda(0));
    }
}
