//! C and C++ programs built against the installed library (`scripts/install-c`),
//! through pkg-config and through CMake's `find_package(envlight)`, linked
//! statically and dynamically: their rows equal the Rust library's bit for bit
//! on a synthetic map and a real one (a visibility cache built through a C
//! callback and a C++ lambda included); every error path is a status and a
//! message;
//! the header compiles as C99, C11 and C++17 with warnings as errors; the C
//! programs and the C++ visibility program run clean under valgrind memcheck;
//! eight threads on one light, and four on one visibility cache, give the
//! single-threaded rows; the shared library exports only `envlight_*`.
//!
//! The installed prefix comes from `ENVLIGHT_C_PREFIX` (`bash scripts/test` sets
//! it after installing into `target/c-prefix`). Without it, or without a C
//! toolchain, cmake, pkg-config or valgrind, each test prints why and skips;
//! with `ENVLIGHT_REQUIRE_C=1` (CI) it fails instead.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use envlight::visibility::VisibilityOptions;
use envlight::{
    EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3, VisibilityCache,
};

/// The C sources: rows.c, rows.cpp, errors.c, visibility.c, visibility.cpp,
/// CMakeLists.txt.
fn sources() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/c")
}

/// Prints why a test cannot run and returns, or fails under `ENVLIGHT_REQUIRE_C`.
fn skip(why: &str) {
    if std::env::var_os("ENVLIGHT_REQUIRE_C").is_some_and(|v| v != "0") {
        panic!("ENVLIGHT_REQUIRE_C is set, but {why}");
    }
    eprintln!("skipping: {why}");
}

/// The warnings every program and header here is compiled with, as errors.
const WARNINGS: [&str; 4] = ["-Wall", "-Wextra", "-Werror", "-pedantic"];

fn have(tool: &str) -> bool {
    Command::new(tool).arg("--version").output().is_ok()
}

/// Runs `command`, returning its stdout; panics with its stderr on failure.
fn run(command: &mut Command) -> String {
    let output = command
        .output()
        .unwrap_or_else(|e| panic!("cannot run {command:?}: {e}"));
    assert!(
        output.status.success(),
        "{command:?} failed ({}):\n{}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).expect("UTF-8 output")
}

/// The installed prefix and a work folder with every program built.
struct Built {
    prefix: PathBuf,
    work: tempfile::TempDir,
    /// name → executable: `pc_c_shared`, `pc_c_static`, `pc_cpp_shared`,
    /// `pc_cpp_static`, `pc_errors_shared`, `pc_visibility_shared`,
    /// `pc_visibility_cpp_shared`, ..., and CMake's `cmake_rows_shared`, ...
    programs: BTreeMap<String, PathBuf>,
}

/// Everything built once for all tests, or the reason it cannot be.
fn built() -> Result<&'static Built, String> {
    static BUILT: OnceLock<Result<Built, String>> = OnceLock::new();
    BUILT.get_or_init(build).as_ref().map_err(Clone::clone)
}

fn build() -> Result<Built, String> {
    let prefix = std::env::var_os("ENVLIGHT_C_PREFIX")
        .map(PathBuf::from)
        .ok_or(
            "ENVLIGHT_C_PREFIX is not set (bash scripts/test installs the library and sets it)",
        )?;
    if !prefix.join("include/envlight.h").is_file() {
        return Err(format!("{} holds no installed envlight", prefix.display()));
    }
    for tool in ["cc", "c++", "pkg-config", "cmake"] {
        if !have(tool) {
            return Err(format!("{tool} is not installed"));
        }
    }
    let work = tempfile::tempdir().map_err(|e| e.to_string())?;
    let src = sources();
    let pc = |args: &[&str]| -> Vec<String> {
        let out = run(Command::new("pkg-config")
            .args(args)
            .env("PKG_CONFIG_PATH", prefix.join("lib/pkgconfig")));
        out.split_whitespace().map(String::from).collect()
    };
    let mut programs = BTreeMap::new();
    // pkg-config: the shared package and the static one.
    for (kind, package) in [("shared", "envlight"), ("static", "envlight-static")] {
        let flags = pc(&["--cflags", "--libs", package]);
        // `compiler std source flags extra -o pc_NAME_KIND`.
        let mut compile = |name: &str, compiler: &str, std: &str, source: &str, extra: &[&str]| {
            let exe = work.path().join(format!("pc_{name}_{kind}"));
            run(Command::new(compiler)
                .arg(std)
                .args(WARNINGS)
                .arg(src.join(source))
                .args(&flags)
                .args(extra)
                .arg("-o")
                .arg(&exe));
            programs.insert(format!("pc_{name}_{kind}"), exe);
        };
        compile("c", "cc", "-std=c99", "rows.c", &["-pthread"]);
        compile("cpp", "c++", "-std=c++17", "rows.cpp", &[]);
        compile("errors", "cc", "-std=c11", "errors.c", &["-lm"]);
        compile(
            "visibility",
            "cc",
            "-std=c99",
            "visibility.c",
            &["-lm", "-pthread"],
        );
        compile("visibility_cpp", "c++", "-std=c++17", "visibility.cpp", &[]);
    }
    // CMake: find_package(envlight) from the prefix.
    let cmake = work.path().join("cmake");
    run(Command::new("cmake")
        .arg("-S")
        .arg(&src)
        .arg("-B")
        .arg(&cmake)
        .arg(format!("-DCMAKE_PREFIX_PATH={}", prefix.display()))
        .arg("-DCMAKE_BUILD_TYPE=Release"));
    run(Command::new("cmake").arg("--build").arg(&cmake).arg("-j2"));
    for kind in ["shared", "static"] {
        for name in ["rows", "rows_cpp", "errors", "visibility", "visibility_cpp"] {
            let name = format!("{name}_{kind}");
            programs.insert(format!("cmake_{name}"), cmake.join(&name));
        }
    }
    Ok(Built {
        prefix,
        work,
        programs,
    })
}

/// `built()`, or `None` after printing why the test skips.
fn programs() -> Option<&'static Built> {
    match built() {
        Ok(b) => Some(b),
        Err(why) => {
            skip(&why);
            None
        }
    }
}

/// The inputs every program reads: `n` points `u` and `n` unit directions.
struct Inputs {
    u: Vec<[f32; 2]>,
    dirs: Vec<Vec3>,
    path: PathBuf,
}

fn inputs(dir: &Path, n: usize) -> Inputs {
    let u: Vec<[f32; 2]> = (0..n as u64).map(|k| envlight::rng::xi_2d(11, k)).collect();
    let mut dirs: Vec<Vec3> = (0..n as u64)
        .map(|k| envlight::math::uniform_sphere(envlight::rng::xi_2d(12, k)))
        .collect();
    // The axes and a pole too.
    dirs[0] = Vec3::new(0.0, 0.0, 1.0);
    dirs[1] = Vec3::new(1.0, 0.0, 0.0);
    dirs[2] = Vec3::new(0.0, -1.0, 0.0);
    let mut bytes = (n as u32).to_le_bytes().to_vec();
    for v in u.iter().flatten() {
        bytes.extend(v.to_le_bytes());
    }
    for d in &dirs {
        for v in d.to_array() {
            bytes.extend(v.to_le_bytes());
        }
    }
    let path = dir.join(format!("inputs-{n}.bin"));
    std::fs::write(&path, bytes).unwrap();
    Inputs { u, dirs, path }
}

/// A map to test on: its argument for the programs and the Rust light.
struct Map {
    arg: String,
    light: std::sync::Arc<EnvironmentLight>,
}

/// A synthetic sun-and-sky map, written as the programs' raw format.
fn synthetic(dir: &Path, w: usize, h: usize) -> Map {
    let image = envlight::builtin::sky(w, h);
    let mut bytes = (w as u32).to_le_bytes().to_vec();
    bytes.extend((h as u32).to_le_bytes());
    for v in image.texels().iter().flatten() {
        bytes.extend(v.to_le_bytes());
    }
    let path = dir.join(format!("sky-{w}x{h}.raw"));
    std::fs::write(&path, bytes).unwrap();
    Map {
        arg: format!("raw:{}", path.display()),
        light: std::sync::Arc::new(EnvironmentLight::new(image, LightOptions::default()).unwrap()),
    }
}

/// A real map from ../shared/envmaps, when present.
fn real() -> Option<Map> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps/sunrise.exr");
    if !path.is_file() {
        eprintln!(
            "skipping the real map: {} is absent (the shared maps sit beside the checkout)",
            path.display()
        );
        return None;
    }
    let image = envlight::load::load(&path, &Default::default())
        .unwrap()
        .image;
    Some(Map {
        arg: path.display().to_string(),
        light: std::sync::Arc::new(EnvironmentLight::new(image, LightOptions::default()).unwrap()),
    })
}

fn hex(x: f32) -> String {
    format!("{:08x}", x.to_bits())
}

/// The rows the programs print, computed by the Rust library, by their first two
/// words ("S 12").
fn expected_rows(map: &Map, inputs: &Inputs) -> BTreeMap<String, String> {
    let light = &map.light;
    let product = ProductSampler::new(light.clone(), ProductOptions::default());
    let sample_words = |s: Option<envlight::LightSample>, with_radiance: bool| -> String {
        let (ok, d, pdf, l) = match s {
            Some(s) => (1, s.direction.to_array(), s.pdf, s.radiance),
            None => (0, [0.0; 3], 0.0, [0.0; 3]),
        };
        let mut words = vec![ok.to_string()];
        words.extend(d.iter().map(|&x| hex(x)));
        words.push(hex(pdf));
        if with_radiance {
            words.extend(l.iter().map(|&x| hex(x)));
        }
        words.join(" ")
    };
    let mut rows = BTreeMap::new();
    let n = inputs.u.len();
    for k in 0..n {
        let (u, d) = (inputs.u[k], inputs.dirs[k]);
        rows.insert(format!("S {k}"), sample_words(light.sample(u), true));
        rows.insert(format!("P {k}"), hex(light.pdf(d)));
        let l = light.radiance(d);
        rows.insert(
            format!("L {k}"),
            l.iter().map(|&x| hex(x)).collect::<Vec<_>>().join(" "),
        );
        let cosine = Factor::cosine(d);
        rows.insert(
            format!("C {k}"),
            sample_words(product.sample(&cosine, u), false),
        );
        let glossy = Factor::glossy(d, inputs.dirs[(k + 1) % n], 0.3);
        let g = product.sample(&glossy, u);
        rows.insert(format!("G {k}"), sample_words(g, true));
        let gd = g.map_or(Vec3::new(0.0, 0.0, 0.0), |s| s.direction);
        rows.insert(format!("Q {k}"), hex(product.pdf(&glossy, gd)));
    }
    let [r, g, b] = light.integral_rgb();
    let (max, brightest) = light.brightest();
    let [tw, th] = light.table_size();
    let words: Vec<String> = [
        light.image().width().to_string(),
        light.image().height().to_string(),
        tw.to_string(),
        th.to_string(),
    ]
    .into_iter()
    .chain(
        [r, g, b, light.integral_luminance()]
            .iter()
            .map(|x| format!("{:016x}", x.to_bits())),
    )
    .chain(std::iter::once(hex(max)))
    .chain(brightest.to_array().iter().map(|&x| hex(x)))
    .collect();
    rows.insert("I".into(), words.join(" "));
    rows
}

/// Runs `program` on `map` and checks every row it prints against the library's,
/// and that it printed every row of `kinds` for each input (and the info row,
/// for the C programs, which print the product's glossy rows "G").
fn check_program(program: &Path, map: &Map, inputs: &Inputs, kinds: &[&str]) {
    let out = run(Command::new(program).arg(&map.arg).arg(&inputs.path));
    let expected = expected_rows(map, inputs);
    let mut seen = 0;
    for line in out.lines() {
        let (key, rest) = match line.split_once(' ') {
            Some(("I", rest)) => ("I".to_string(), rest),
            Some((kind, rest)) => {
                let (k, rest) = rest.split_once(' ').unwrap_or((rest, ""));
                (format!("{kind} {k}"), rest)
            }
            None => panic!("{}: unexpected line {line:?}", program.display()),
        };
        let want = expected
            .get(&key)
            .unwrap_or_else(|| panic!("{}: unexpected row {line:?}", program.display()));
        assert_eq!(
            rest,
            want,
            "{} on {}: row {key} differs from the Rust library's",
            program.display(),
            map.arg
        );
        seen += 1;
    }
    let n = inputs.u.len();
    if kinds.contains(&"G") {
        assert!(out.starts_with("I "), "{}: no info row", program.display());
    }
    assert!(
        seen >= kinds.len() * n,
        "{}: {seen} rows, expected at least {}",
        program.display(),
        kinds.len() * n
    );
    for kind in kinds {
        for k in [0, n / 2, n - 1] {
            assert!(
                out.contains(&format!("\n{kind} {k} ")) || out.starts_with(&format!("{kind} {k} ")),
                "{}: no row {kind} {k}",
                program.display()
            );
        }
    }
}

#[test]
fn programs_give_the_rust_librarys_rows_bit_for_bit() {
    let Some(b) = programs() else { return };
    let inputs = inputs(b.work.path(), 1000);
    let mut maps = vec![synthetic(b.work.path(), 128, 64)];
    maps.extend(real());
    for map in &maps {
        for (name, program) in &b.programs {
            if name.contains("errors") || name.contains("visibility") {
                continue;
            }
            let kinds: &[&str] = if name.contains("cpp") {
                &["S", "P", "L", "C"]
            } else {
                &["S", "P", "L", "C", "G", "Q"]
            };
            check_program(program, map, &inputs, kinds);
            eprintln!("{name} on {}: rows equal the library's", map.arg);
        }
    }
}

/// The visibility programs' query point `k` and its normal (their header says
/// which).
fn query_point(k: u32) -> (Vec3, Vec3) {
    let (a, b) = ((k % 19) as f32 / 10.0 - 0.9, (k % 17) as f32 / 9.0 - 0.9);
    let up = Vec3::new(0.0, 0.0, 1.0);
    match k % 6 {
        2 | 3 => (Vec3::new(-1.0, a, b + 1.0), Vec3::new(1.0, 0.0, 0.0)),
        4 => (Vec3::new(5.0 + a, b, 3.0), up),
        5 => (
            Vec3::new(a, b, 0.0),
            Vec3::new(0.0, 0.0, if k % 12 == 5 { 3.0 } else { 0.0 }),
        ),
        _ => (Vec3::new(a, b, 0.0), up),
    }
}

/// The rows the visibility programs print, computed by the Rust library: the
/// same cache built from the same points, rays and options.
fn expected_visibility_rows(map: &Map, inputs: &Inputs) -> BTreeMap<String, String> {
    let product = std::sync::Arc::new(ProductSampler::new(
        map.light.clone(),
        ProductOptions::default(),
    ));
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for i in 0..20 {
        for j in 0..20 {
            let (a, b) = ((i as f32 + 0.5) / 10.0 - 1.0, (j as f32 + 0.5) / 10.0 - 1.0);
            points.extend([Vec3::new(a, b, 0.0), Vec3::new(-1.0, a, b + 1.0)]);
            normals.extend([Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 0.0)]);
        }
    }
    let options = VisibilityOptions {
        seed: 7,
        rays_per_patch: 2,
        ..VisibilityOptions::default()
    };
    let mut rays = 0u64;
    let trace = |o: &[Vec3], d: &[Vec3], t: &mut [f32]| -> Result<(), std::convert::Infallible> {
        rays += o.len() as u64;
        for ((o, d), t) in o.iter().zip(d).zip(t.iter_mut()) {
            *t = room::room_transmittance(o.to_array(), d.to_array());
        }
        Ok(())
    };
    let cache = VisibilityCache::build(product, &points, &normals, &options, trace).unwrap();
    let s = cache.summary();
    let mut rows = BTreeMap::new();
    rows.insert(
        "Y".to_string(),
        format!(
            "{} {} {} {:016x} {}",
            s.entries,
            s.bytes,
            hex(s.radius),
            s.mean_visibility.to_bits(),
            s.rays
        ),
    );
    rows.insert("T".to_string(), rays.to_string());
    for k in 0..inputs.u.len() {
        let (p, n) = query_point(k as u32);
        let at = cache.at(p, &Factor::cosine(n));
        let (ok, d, pdf, l) = match at.sample(inputs.u[k]) {
            Some(s) => (1, s.direction.to_array(), s.pdf, s.radiance),
            None => (0, [0.0; 3], 0.0, [0.0; 3]),
        };
        let mut words = vec![ok.to_string()];
        words.extend(
            d.iter()
                .chain([pdf].iter())
                .chain(l.iter())
                .map(|&x| hex(x)),
        );
        rows.insert(format!("V {k}"), words.join(" "));
        rows.insert(format!("W {k}"), hex(at.pdf(inputs.dirs[k])));
    }
    rows
}

#[test]
fn visibility_programs_give_the_rust_librarys_rows_bit_for_bit() {
    let Some(b) = programs() else { return };
    let inputs = inputs(b.work.path(), 600);
    let mut maps = vec![synthetic(b.work.path(), 128, 64)];
    maps.extend(real());
    for map in &maps {
        let expected = expected_visibility_rows(map, &inputs);
        for (name, program) in b.programs.iter().filter(|(n, _)| n.contains("visibility")) {
            let dir = tempfile::tempdir().unwrap();
            let out = run(Command::new(program)
                .arg(&map.arg)
                .arg(&inputs.path)
                .arg(dir.path()));
            let mut seen = 0;
            for line in out.lines() {
                let (kind, rest) = line.split_once(' ').unwrap_or((line, ""));
                let (key, rest) = match kind {
                    "V" | "W" => {
                        let (k, rest) = rest.split_once(' ').unwrap_or((rest, ""));
                        (format!("{kind} {k}"), rest)
                    }
                    _ => (kind.to_string(), rest),
                };
                let want = expected
                    .get(&key)
                    .unwrap_or_else(|| panic!("{name}: unexpected row {line:?}"));
                assert_eq!(
                    rest, want,
                    "{name} on {}: row {key} differs from the Rust library's",
                    map.arg
                );
                seen += 1;
            }
            assert_eq!(
                seen,
                expected.len(),
                "{name}: {seen} rows of {}",
                expected.len()
            );
            eprintln!("{name} on {}: rows equal the library's", map.arg);
        }
    }
}

#[test]
fn error_paths_are_statuses_and_messages() {
    let Some(b) = programs() else { return };
    for (name, program) in &b.programs {
        if name.contains("errors") {
            let out = run(Command::new(program).arg(b.work.path()));
            assert!(out.ends_with("0 failures\n"), "{name}:\n{out}");
            assert!(
                out.lines().count() > 40,
                "{name} ran too few checks:\n{out}"
            );
        }
    }
}

/// A 612-byte OpenEXR file that once made the loader reserve 1.9 GB (a fuzzing
/// find): under a 512 MiB address-space limit, where that reservation aborted the
/// process, loading it must be a status and a message naming it.
#[test]
fn a_hostile_file_is_a_status_under_a_512_mib_address_space_limit() {
    let Some(b) = programs() else { return };
    let hostile = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/regressions/load/exr-chunk-size-1.9GB.exr");
    assert!(
        hostile.is_file(),
        "{} is in the repository",
        hostile.display()
    );
    for name in ["pc_errors_shared", "cmake_errors_static"] {
        let out = run(Command::new("sh")
            .args(["-c", "ulimit -v 524288 && exec \"$@\"", "sh"])
            .arg(&b.programs[name])
            .arg(b.work.path())
            .arg(&hostile));
        assert!(out.ends_with("0 failures\n"), "{name}:\n{out}");
    }
}

#[test]
fn eight_threads_get_the_single_threaded_rows() {
    let Some(b) = programs() else { return };
    let inputs = inputs(b.work.path(), 4000);
    let map = synthetic(b.work.path(), 256, 128);
    for name in ["pc_c_shared", "cmake_rows_static"] {
        let out = run(Command::new(&b.programs[name])
            .arg(&map.arg)
            .arg(&inputs.path)
            .args(["--threads", "8"]));
        assert!(
            out.starts_with("threads 8 identical\n"),
            "{name}: {out:.200}"
        );
    }
}

#[test]
fn header_compiles_as_c99_c11_and_cpp17_with_warnings_as_errors() {
    let Some(b) = programs() else { return };
    let include = b.prefix.join("include");
    let c = b.work.path().join("header.c");
    std::fs::write(
        &c,
        "#include <envlight.h>\nint main(void) { return envlight_version() == 0; }\n",
    )
    .unwrap();
    for std in ["-std=c99", "-std=c11"] {
        run(Command::new("cc")
            .arg(std)
            .args(WARNINGS)
            .arg("-c")
            .arg("-I")
            .arg(&include)
            .arg(&c)
            .arg("-o")
            .arg(b.work.path().join("header.o")));
    }
    let cpp = b.work.path().join("header.cpp");
    std::fs::write(
        &cpp,
        "#include <envlight.hpp>\n#include <envlight.h>\nint main() { return envlight::version().empty(); }\n",
    )
    .unwrap();
    run(Command::new("c++")
        .arg("-std=c++17")
        .args(WARNINGS)
        .arg("-c")
        .arg("-I")
        .arg(&include)
        .arg(&cpp)
        .arg("-o")
        .arg(b.work.path().join("header_cpp.o")));
}

#[test]
fn c_programs_run_clean_under_valgrind() {
    let Some(b) = programs() else { return };
    if !have("valgrind") {
        return skip("valgrind is not installed");
    }
    let inputs = inputs(b.work.path(), 64);
    let map = synthetic(b.work.path(), 32, 16);
    let memcheck = |program: &Path, args: &[&std::ffi::OsStr]| {
        run(Command::new("valgrind")
            .args([
                "--error-exitcode=97",
                "--leak-check=full",
                "--errors-for-leak-kinds=definite,indirect",
                "--show-leak-kinds=definite,indirect",
                "-q",
            ])
            .arg(program)
            .args(args));
    };
    for kind in ["shared", "static"] {
        memcheck(
            &b.programs[&format!("pc_errors_{kind}")],
            &[b.work.path().as_os_str()],
        );
        memcheck(
            &b.programs[&format!("pc_c_{kind}")],
            &[
                map.arg.as_ref(),
                inputs.path.as_os_str(),
                "--threads".as_ref(),
                "2".as_ref(),
            ],
        );
        for program in ["visibility", "visibility_cpp"] {
            let dir = tempfile::tempdir().unwrap();
            memcheck(
                &b.programs[&format!("pc_{program}_{kind}")],
                &[
                    map.arg.as_ref(),
                    inputs.path.as_os_str(),
                    dir.path().as_os_str(),
                ],
            );
        }
    }
}

#[test]
fn shared_library_exports_only_envlight_symbols() {
    let Some(b) = programs() else { return };
    let lib = b.prefix.join("lib/libenvlight.so");
    let out = run(Command::new("nm").args(["-D", "--defined-only"]).arg(&lib));
    let names: Vec<&str> = out
        .lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .collect();
    assert!(names.contains(&"envlight_light_sample_batch"), "{}", out);
    let foreign: Vec<&&str> = names
        .iter()
        .filter(|n| !n.starts_with("envlight_"))
        .collect();
    assert!(foreign.is_empty(), "symbols beyond envlight_*: {foreign:?}");
    let soname = run(Command::new("objdump").arg("-p").arg(&lib));
    assert!(
        soname.contains("SONAME               libenvlight.so.0"),
        "{soname}"
    );
}

#[path = "../../envlight-cli/tests/common/doc_blocks.rs"]
mod doc_blocks;

/// The room `tests/c/visibility.c` traces.
#[path = "common/room.rs"]
mod room;

/// Every `c`, `cpp` and `cmake` block of README.md and docs/*.md, as a newcomer
/// would use it: a C program (one with `main`) built through pkg-config, shared and
/// static, and run with no argument and with a map file; C declarations (no
/// `main`) compiled after `#include <envlight.h>`, so they must match the header;
/// C++ likewise with `envlight.hpp`; a CMake fragment appended to a project that
/// builds a one-line program `app` and runs it.
#[test]
fn docs_code_blocks_build_and_run() {
    let Some(b) = programs() else { return };
    let maps: Vec<String> = real().map(|m| m.arg).into_iter().collect();
    let pc = |package: &str| -> Vec<String> {
        run(Command::new("pkg-config")
            .args(["--cflags", "--libs", package])
            .env("PKG_CONFIG_PATH", b.prefix.join("lib/pkgconfig")))
        .split_whitespace()
        .map(str::to_string)
        .collect()
    };
    let mut checked = 0;
    for block in doc_blocks::all_blocks() {
        let name = format!(
            "doc_{}_{}",
            block.file.replace(['/', '.', '-'], "_"),
            block.line
        );
        let dir = b.work.path().join(&name);
        std::fs::create_dir_all(&dir).unwrap();
        let has_main = block.code.contains("main(");
        match block.info.as_str() {
            "c" | "cpp" => {
                let cpp = block.info == "cpp";
                let (compiler, std, header, ext) = if cpp {
                    ("c++", "-std=c++17", "envlight.hpp", "cpp")
                } else {
                    ("cc", "-std=c11", "envlight.h", "c")
                };
                let source = dir.join(format!("block.{ext}"));
                let code = if has_main {
                    block.code.clone()
                } else {
                    format!("#include <{header}>\n{}", block.code)
                };
                std::fs::write(&source, code).unwrap();
                let packages: &[&str] = if has_main {
                    &["envlight", "envlight-static"]
                } else {
                    &["envlight"]
                };
                for package in packages {
                    let exe = dir.join(format!("block-{package}"));
                    let mut command = Command::new(compiler);
                    command.arg(std).args(WARNINGS).arg(&source);
                    if has_main {
                        command.args(pc(package)).arg("-o").arg(&exe);
                    } else {
                        // A declaration may spell a pointer as an array (`const
                        // float u[2]`) for the reader: the same type in C.
                        command
                            .args(pc(package))
                            .args(["-fsyntax-only", "-Wno-array-parameter"]);
                    }
                    run(&mut command);
                    if has_main {
                        run(&mut Command::new(&exe));
                        for map in &maps {
                            run(Command::new(&exe).arg(map));
                        }
                    }
                }
            }
            "cmake" => {
                std::fs::write(
                    dir.join("CMakeLists.txt"),
                    format!(
                        "cmake_minimum_required(VERSION 3.16)\nproject(docs_block C)\n\
                         add_executable(app app.c)\n{}",
                        block.code
                    ),
                )
                .unwrap();
                std::fs::write(
                    dir.join("app.c"),
                    "#include <envlight.h>\nint main(void) {\n    \
                     envlight_light_options o = envlight_light_options_default();\n    \
                     return o.scale == 1.0f ? 0 : 1;\n}\n",
                )
                .unwrap();
                let build = dir.join("build");
                run(Command::new("cmake")
                    .arg("-S")
                    .arg(&dir)
                    .arg("-B")
                    .arg(&build)
                    .arg(format!("-DCMAKE_PREFIX_PATH={}", b.prefix.display())));
                run(Command::new("cmake").arg("--build").arg(&build));
                run(&mut Command::new(build.join("app")));
            }
            _ => continue,
        }
        println!(
            "{}:{} ```{}: built{}",
            block.file,
            block.line,
            block.info,
            if has_main { " and ran" } else { "" }
        );
        checked += 1;
    }
    assert!(
        checked > 0,
        "no C, C++ or CMake block in README.md or docs/"
    );
}
