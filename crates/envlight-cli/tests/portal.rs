//! `--portal` and `--at` on `sample`, `eval` and `verify` (issue 25): the output
//! contract is unchanged, samples pass through the portals, `eval` reproduces the
//! pdfs of `sample`, and every malformed request is a usage error (exit 2) that
//! says why.

use predicates::prelude::*;

mod common;
use common::{envlight, parse_rows, stdout_of};

const WINDOW: &str = "4,1,0.8;4,2.2,0.8;4,2.2,1.9;4,1,1.9";
const SKYLIGHT: &str = "1.2,1,2.5;2.4,1,2.5;2.4,2,2.5;1.2,2,2.5";
const CENTRE: &str = "2,1.5,1.2";

/// Whether the ray from `p` along `d` crosses the axis-aligned rectangle `quad`
/// (one coordinate constant), by the test's own arithmetic.
fn crosses(p: [f64; 3], d: [f64; 3], quad: [[f64; 3]; 4]) -> bool {
    let axis = (0..3)
        .find(|&a| quad.iter().all(|c| c[a] == quad[0][a]))
        .unwrap();
    let t = (quad[0][axis] - p[axis]) / d[axis];
    // NaN (a direction parallel to the plane) crosses nothing either.
    if t.is_nan() || t <= 0.0 {
        return false;
    }
    (0..3).filter(|&a| a != axis).all(|a| {
        let x = p[a] + t * d[a];
        let lo = quad.iter().map(|c| c[a]).fold(f64::INFINITY, f64::min);
        let hi = quad.iter().map(|c| c[a]).fold(f64::NEG_INFINITY, f64::max);
        x >= lo - 1e-6 && x <= hi + 1e-6
    })
}

fn quad(text: &str) -> [[f64; 3]; 4] {
    let c: Vec<[f64; 3]> = text
        .split(';')
        .map(|p| {
            let v: Vec<f64> = p.split(',').map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    [c[0], c[1], c[2], c[3]]
}

#[test]
fn sample_goes_through_the_portals_and_eval_agrees() {
    let args = ["--portal", WINDOW, "--portal", SKYLIGHT, "--at", CENTRE];
    let out = stdout_of(
        envlight()
            .args(["sample", "-n", "2000", "--seed", "3"])
            .args(args),
    );
    let samples = parse_rows(&out);
    assert_eq!(samples.len(), 2000);
    let p = [2.0, 1.5, 1.2];
    let (w, s) = (quad(WINDOW), quad(SKYLIGHT));
    for r in &samples {
        let d = [r[0], r[1], r[2]];
        assert!(r[3] > 0.0, "{r:?}");
        assert!(
            crosses(p, d, w) || crosses(p, d, s),
            "{r:?} misses both portals"
        );
    }
    // Deterministic per seed.
    let again = stdout_of(
        envlight()
            .args(["sample", "-n", "2000", "--seed", "3"])
            .args(args),
    );
    assert_eq!(out, again);
    // eval reproduces the rows, and gives 0 through no portal.
    let mut dirs = String::from("x,y,z\n");
    for r in &samples[..200] {
        dirs.push_str(&format!("{},{},{}\n", r[0], r[1], r[2]));
    }
    dirs.push_str("0,0,-1\n-1,0,0\n");
    let evals = stdout_of(
        envlight()
            .args(["eval", "--dirs", "-"])
            .args(args)
            .write_stdin(dirs),
    );
    let evals = parse_rows(&evals);
    for (e, r) in evals.iter().zip(&samples[..200]) {
        assert_eq!(e, r);
    }
    assert_eq!(evals[200][3], 0.0);
    assert_eq!(evals[201][3], 0.0);
}

#[test]
fn verify_passes_and_a_point_that_sees_nothing_is_skipped() {
    envlight()
        .args([
            "verify",
            "--samples",
            "50000",
            "--portal",
            WINDOW,
            "--portal",
            SKYLIGHT,
        ])
        .args(["--at", CENTRE])
        .assert()
        .success()
        .stdout(predicate::str::contains("through a portal"))
        .stdout(predicate::str::contains("all checks passed"));
    envlight()
        .args([
            "verify",
            "--samples",
            "1000",
            "--portal",
            WINDOW,
            "--portal",
            SKYLIGHT,
        ])
        .args(["--at", "4,0.5,2.5"])
        .assert()
        .success()
        .stdout(predicate::str::contains(
            "nothing lit is seen through the portals",
        ));
    // Sampling from there gives rows of pdf 0.
    let out = stdout_of(envlight().args([
        "sample",
        "-n",
        "10",
        "--portal",
        WINDOW,
        "--at",
        "4,0.5,2.5",
    ]));
    assert!(parse_rows(&out).iter().all(|r| r[3] == 0.0));
}

#[test]
fn bad_requests_are_usage_errors_that_say_why() {
    let cases: [(&[&str], &str); 8] = [
        (
            &["sample", "-n", "1", "--portal", WINDOW],
            "--portal needs --at",
        ),
        (
            &["eval", "--dirs", "-", "--at", CENTRE],
            "--at needs at least one --portal",
        ),
        (
            &[
                "sample",
                "-n",
                "1",
                "--portal",
                "0,0,0;1,0,0;1,1,0.5;0,1,0",
                "--at",
                CENTRE,
            ],
            "not planar",
        ),
        (
            &[
                "sample",
                "-n",
                "1",
                "--portal",
                "0,0,0;1,0,0;2,0,0;3,0,0",
                "--at",
                CENTRE,
            ],
            "degenerate",
        ),
        (
            &["verify", "--portal", "0,0,0;1,0,0;1,1,0", "--at", CENTRE],
            "four corners",
        ),
        (
            &[
                "sample",
                "-n",
                "1",
                "--portal",
                "0,0,0;1,1,0;1,0,0;0,1,0",
                "--at",
                CENTRE,
            ],
            "convex",
        ),
        (
            &["sample", "-n", "1", "--portal", WINDOW, "--at", "1,2"],
            "three comma-separated",
        ),
        (
            &[
                "sample", "-n", "1", "--portal", WINDOW, "--at", CENTRE, "--normal", "0,0,1",
            ],
            "cannot be combined",
        ),
    ];
    for (args, why) in cases {
        envlight()
            .args(args)
            .write_stdin("x,y,z\n0,0,1\n")
            .assert()
            .code(2)
            .stderr(predicate::str::contains("error:"))
            .stderr(predicate::str::contains(why));
    }
}
