//! The GPU adapter for the GPU suites: opened once per test binary. A test that needs one
//! must not pass quietly without it: under CI (`CI` set, as `.ci/run` does, which installs
//! lavapipe) no adapter is a failure; elsewhere the test writes `SKIPPED: ...` to the real
//! stderr and returns early.

use std::sync::OnceLock;

use subfield::gpu::{AdapterPolicy, GpuDevice};

static DEVICE: OnceLock<Result<GpuDevice, String>> = OnceLock::new();

/// The adapter (`--device gpu`'s choice), or `None` after saying why the test skips.
#[track_caller]
pub fn device() -> Option<&'static GpuDevice> {
    let d = DEVICE.get_or_init(|| match GpuDevice::open(AdapterPolicy::Any) {
        Ok(Some(d)) => Ok(d),
        Ok(None) => Err("no adapter".into()),
        Err(e) => Err(e.to_string()),
    });
    match d {
        Ok(d) => Some(d),
        Err(e) => {
            let here = std::panic::Location::caller();
            if std::env::var_os("CI").is_some() {
                panic!("no GPU adapter under CI ({here}): {e}");
            }
            use std::io::Write;
            let _ = writeln!(std::io::stderr(), "SKIPPED: {here}: no GPU adapter: {e}");
            None
        }
    }
}
