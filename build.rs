//! With the `tch` feature: put libtorch's library folder (as torch-sys found it) into the rpath of
//! this package's binaries, so `equiarm --device torch` runs without LD_LIBRARY_PATH. Nothing
//! otherwise.

fn main() {
    println!("cargo:rerun-if-env-changed=DEP_TCH_LIBTORCH_LIB");
    if std::env::var_os("CARGO_FEATURE_TCH").is_none() {
        return;
    }
    match std::env::var("DEP_TCH_LIBTORCH_LIB") {
        Ok(dir) if !dir.is_empty() => println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}"),
        _ => println!("cargo:warning=torch-sys did not report libtorch's library folder: set LD_LIBRARY_PATH to run with --device torch"),
    }
}
