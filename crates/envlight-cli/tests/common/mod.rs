//! Helpers shared by the integration tests that run the `envlight` binary.

#![allow(dead_code)]

use std::path::Path;

use assert_cmd::Command;

/// The CSV header of `sample` and `eval`.
pub const HEADER: &str = "x,y,z,pdf,r,g,b";

/// The `envlight` binary, built by cargo for the tests.
pub fn envlight() -> Command {
    Command::cargo_bin("envlight").expect("the envlight binary is built")
}

/// Writes a colour PFM by hand: `PF`, size, a negative scale (little-endian), then
/// f32 RGB rows bottom to top. `texel(x, y)` has y = 0 at the top.
pub fn write_pfm(path: &Path, w: usize, h: usize, texel: impl Fn(usize, usize) -> [f32; 3]) {
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for y in (0..h).rev() {
        for x in 0..w {
            for c in texel(x, y) {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// Runs `cmd`, which must succeed; its stdout.
pub fn stdout_of(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{:?} failed: {}",
        cmd,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The rows of `sample` or `eval` output (after the exact header), seven numbers each.
pub fn parse_rows(csv: &str) -> Vec<[f64; 7]> {
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(HEADER));
    lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|f| f.parse().unwrap()).collect();
            assert_eq!(v.len(), 7, "{l}");
            [v[0], v[1], v[2], v[3], v[4], v[5], v[6]]
        })
        .collect()
}

/// `envlight importance ARGS -o PNG` succeeds, quietly.
pub fn importance(args: &[&str], png: &Path) {
    let stdout = stdout_of(envlight().arg("importance").args(args).arg("-o").arg(png));
    assert_eq!(stdout, "");
}
