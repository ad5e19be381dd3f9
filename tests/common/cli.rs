//! Running the `vkterrain` binary from integration tests.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The binary with validation on and no device override from the environment.
pub fn command() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_vkterrain"));
    c.env("VKTERRAIN_VALIDATION", "1")
        .env_remove("VKTERRAIN_DEVICE");
    c
}

/// Runs `vkterrain ARGS...` to completion.
pub fn run(args: &[&str]) -> Output {
    command().args(args).output().expect("run vkterrain")
}

/// A config file shipped in `config/`.
pub fn shipped_config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name)
}

/// `config/ci.toml` as a string argument.
pub fn ci_config() -> String {
    shipped_config("ci.toml").display().to_string()
}

/// Asserts `o` failed with status 1 and exactly one line `error: ...` on stderr that mentions
/// every word of `expected`, without a panic; returns that line.
pub fn assert_one_line_error(o: &Output, expected: &[&str]) -> String {
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "status; stderr: {stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "expected one error line, got: {stderr}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    for word in expected {
        assert!(
            lines[0].contains(word),
            "{:?} does not mention {word:?}",
            lines[0]
        );
    }
    lines[0].to_string()
}
