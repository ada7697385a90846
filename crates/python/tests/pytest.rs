//! The Python package's tests (python/tests), run by pytest in a Python where the package is
//! installed: `RLNAV_PYAPI_PYTHON` names it (CI makes the venv: the package with Stable-Baselines3, PyTorch, Ray and pytest).
//! Without it they are skipped here, except under CI, where that is a failure.

use std::path::Path;
use std::process::Command;

#[test]
fn python_package_tests() {
    let Ok(python) = std::env::var("RLNAV_PYAPI_PYTHON") else {
        assert!(
            std::env::var("CI").is_err(),
            "CI must set RLNAV_PYAPI_PYTHON (a venv with the rlnav package installed)"
        );
        eprintln!("RLNAV_PYAPI_PYTHON not set: the Python API tests skipped (CI runs them)");
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let status = Command::new(&python)
        .args(["-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", "python/tests"])
        .current_dir(&root)
        .status()
        .unwrap_or_else(|e| panic!("running {python}: {e}"));
    assert!(status.success(), "pytest python/tests failed ({status}); its output is above");
}
