//! `envlight eval`: pdf and radiance of directions read from CSV.
//!
//! The input is streamed in batches of lines (never read whole); each batch is
//! parsed, evaluated and formatted in parallel and written in input order.

use std::io::{BufRead, BufReader, Read};
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context};
use envlight::Vec3;
use rayon::prelude::*;

use super::Outcome;
use crate::csv::{push_row, HEADER, MAX_ROW_BYTES};
use crate::output::{open_input, write_bytes, Output};
use crate::progress::Progress;
use crate::query::QueryArgs;
use crate::shading::Density;

/// Lines read before a batch is processed.
const BATCH_LINES: usize = 1 << 16;
/// Lines handled by one parallel task.
const TASK_LINES: usize = 4096;
/// Longer lines are refused (they are not direction rows, and must not exhaust memory).
const MAX_LINE_BYTES: usize = 1 << 20;

/// Arguments of `envlight eval`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "Input: CSV whose first line (line 1) is a header naming the columns x, y and z (any \
case), in any order; other columns are ignored, spaces around fields and quotes around a field are \
tolerated, blank lines are skipped; fields must not contain commas. Each direction is \
normalised (it need not be unit length) and must be finite and non-zero.\n\n\
Output: CSV with the header line exactly `x,y,z,pdf,r,g,b`, then one row per input row, \
in order: the normalised world-space direction, the solid-angle pdf (sr⁻¹) with which \
`envlight sample` draws it (with --normal, the product sampler's pdf for that surface \
normal; with --portal and --at, the portal light's pdf at that point, 0 for a direction \
through no portal), and the radiance arriving from it. A bad row stops the \
command with an error naming its line; with -o no output file is left behind. With \
--device gpu the pdf and radiance are computed on the GPU.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    query: QueryArgs,

    /// CSV file of directions, or - for stdin.
    #[arg(long, value_name = "FILE|-")]
    dirs: PathBuf,

    /// Write the CSV to FILE (atomically: all or nothing) instead of stdout.
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    output: Option<PathBuf>,
}

/// Runs `envlight eval`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    args.query.check()?;
    let (mut input, source): (Box<dyn BufRead>, String) = if args.dirs.as_os_str() == "-" {
        (Box::new(std::io::stdin().lock()), "<stdin>".to_string())
    } else {
        let file = open_input(&args.dirs)?;
        (
            Box::new(BufReader::with_capacity(1 << 20, file)),
            args.dirs.display().to_string(),
        )
    };
    // Read the header before the (possibly slow) map, so a wrong file fails fast.
    let mut line = Vec::new();
    let read = read_line(&mut input, &mut line, &source, 1)?;
    if read == 0 {
        bail!("{source}: empty input: expected a header line naming the columns x, y, z");
    }
    let columns = Columns::from_header(&line, &source)?;

    let query = args.query.open()?;
    let light = query.light();
    let density = Density::new(light, query.product.as_ref(), args.query.normal());
    let portal_point = query.portals.as_ref().map(|(pl, at)| pl.at(*at));
    let pdf = |d: Vec3| match &portal_point {
        Some(point) => point.pdf(d),
        None => density.pdf(d),
    };
    let mut out = Output::create(args.output.as_deref())?;
    write_bytes(&mut out, format!("{HEADER}\n").as_bytes())?;

    let progress = Progress::counter("evaluated");
    let mut batch = Batch::default();
    let mut next_line_number = 2u64;
    loop {
        batch.clear(next_line_number);
        let mut eof = false;
        while batch.len() < BATCH_LINES {
            let start = batch.data.len();
            let n = read_line(&mut input, &mut batch.data, &source, next_line_number)?;
            if n == 0 {
                eof = true;
                break;
            }
            batch.ends.push(start + n);
            next_line_number += 1;
        }
        progress.inc(batch.len() as u64);
        let tasks = (0..batch.len()).into_par_iter().step_by(TASK_LINES);
        let range = |first: usize| first..(first + TASK_LINES).min(batch.len());
        let results: Vec<anyhow::Result<Vec<u8>>> = match &query.gpu {
            None => tasks
                .map(|first| {
                    let directions = parse_lines(&columns, &batch, range(first), &source)?;
                    let rows = directions.iter().map(|&d| (d, pdf(d), light.radiance(d)));
                    Ok(format_rows(rows))
                })
                .collect(),
            Some(gpu) => {
                let parsed: anyhow::Result<Vec<Vec<Vec3>>> = tasks
                    .map(|first| parse_lines(&columns, &batch, range(first), &source))
                    .collect();
                let directions: Vec<Vec3> = parsed?.concat();
                let arrays: Vec<[f32; 3]> = directions.iter().map(|d| d.to_array()).collect();
                let evals = gpu.eval(&arrays)?;
                let rows = directions
                    .iter()
                    .zip(&evals)
                    .map(|(&d, e)| (d, e.pdf, e.radiance));
                vec![Ok(format_rows(rows))]
            }
        };
        for result in results {
            write_bytes(&mut out, &result?)?;
        }
        if eof {
            break;
        }
    }
    progress.finish();
    out.finish()?;
    Ok(Outcome::Success)
}

/// Reads one line (including its `\n`) into `buf`, appending; returns the bytes read.
fn read_line(
    input: &mut dyn BufRead,
    buf: &mut Vec<u8>,
    source: &str,
    line_number: u64,
) -> anyhow::Result<usize> {
    let n = (&mut *input)
        .take(MAX_LINE_BYTES as u64 + 1)
        .read_until(b'\n', buf)
        .with_context(|| format!("{source}:{line_number}: read failed"))?;
    if n > MAX_LINE_BYTES {
        bail!("{source}:{line_number}: line is longer than {MAX_LINE_BYTES} bytes");
    }
    Ok(n)
}

/// A batch of input lines stored back to back.
#[derive(Default)]
struct Batch {
    data: Vec<u8>,
    /// End offset of each line in `data`.
    ends: Vec<usize>,
    /// The 1-based line number of the first line.
    first_line_number: u64,
}

impl Batch {
    fn clear(&mut self, first_line_number: u64) {
        self.data.clear();
        self.ends.clear();
        self.first_line_number = first_line_number;
    }

    fn len(&self) -> usize {
        self.ends.len()
    }

    fn line(&self, index: usize) -> &[u8] {
        let start = if index == 0 { 0 } else { self.ends[index - 1] };
        &self.data[start..self.ends[index]]
    }
}

/// Where x, y and z sit among the fields of a row.
struct Columns {
    index: [usize; 3],
    /// Fields needed: one past the largest of `index`.
    needed: usize,
}

impl Columns {
    fn from_header(line: &[u8], source: &str) -> anyhow::Result<Self> {
        let text = std::str::from_utf8(line)
            .map_err(|_| anyhow!("{source}:1: header is not valid UTF-8"))?;
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let names: Vec<&str> = text
            .trim_end_matches(['\n', '\r'])
            .split(',')
            .map(field)
            .collect();
        let mut index = [0usize; 3];
        for (k, want) in ["x", "y", "z"].into_iter().enumerate() {
            let mut found = names
                .iter()
                .enumerate()
                .filter(|(_, n)| n.eq_ignore_ascii_case(want));
            index[k] = match (found.next(), found.next()) {
                (Some((i, _)), None) => i,
                (Some(_), Some(_)) => bail!("{source}:1: header names column {want} twice"),
                (None, _) => bail!(
                    "{source}:1: header has no column named {want} (expected a header line \
                     naming the columns x, y, z; found: {})",
                    names.join(",")
                ),
            };
        }
        let needed = index.iter().max().map_or(0, |m| m + 1);
        Ok(Self { index, needed })
    }
}

/// A field without surrounding whitespace and double quotes.
#[inline]
fn field(raw: &str) -> &str {
    let t = raw.trim();
    t.strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .map_or(t, str::trim)
}

/// The directions of lines `range` of `batch` (blank lines skipped); the first
/// bad line is an error naming it.
fn parse_lines(
    columns: &Columns,
    batch: &Batch,
    range: std::ops::Range<usize>,
    source: &str,
) -> anyhow::Result<Vec<Vec3>> {
    let mut directions = Vec::with_capacity(range.len());
    let mut fields: Vec<&str> = Vec::with_capacity(columns.needed);
    for index in range {
        let line_number = batch.first_line_number + index as u64;
        let bytes = batch.line(index);
        let text = std::str::from_utf8(bytes)
            .map_err(|_| anyhow!("{source}:{line_number}: line is not valid UTF-8"))?;
        let text = text.trim_end_matches(['\n', '\r']);
        if text.trim().is_empty() {
            continue;
        }
        fields.clear();
        fields.extend(text.split(',').take(columns.needed));
        let d = parse_direction(&fields, columns)
            .map_err(|message| anyhow!("{source}:{line_number}: {message}"))?;
        directions.push(d);
    }
    Ok(directions)
}

/// The output rows for `(direction, pdf, radiance)` triples.
fn format_rows(rows: impl ExactSizeIterator<Item = (Vec3, f32, [f32; 3])>) -> Vec<u8> {
    let mut buf = Vec::with_capacity(rows.len() * MAX_ROW_BYTES);
    let mut fmt = ryu::Buffer::new();
    for (d, pdf, radiance) in rows {
        push_row(&mut buf, &mut fmt, d.to_array(), pdf, radiance);
    }
    buf
}

/// How far from 1 a length may be for the direction to count as normalised: a few
/// f32 ulps, the accuracy of a normalised `f32` vector.
const UNIT_TOLERANCE: f64 = 4.0 * f32::EPSILON as f64;

/// The normalised direction of one row, or what is wrong with it.
fn parse_direction(fields: &[&str], columns: &Columns) -> Result<Vec3, String> {
    const NAMES: [&str; 3] = ["x", "y", "z"];
    let mut v = [0.0f64; 3];
    for k in 0..3 {
        let i = columns.index[k];
        let raw = fields.get(i).ok_or_else(|| {
            format!(
                "missing field {} (column {} of the header; the row has {} fields)",
                NAMES[k],
                i + 1,
                fields.len()
            )
        })?;
        let text = field(raw);
        if text.is_empty() {
            return Err(format!("field {} is empty", NAMES[k]));
        }
        v[k] = text
            .parse::<f64>()
            .map_err(|_| format!("field {} is not a number: {text:?}", NAMES[k]))?;
        if !v[k].is_finite() {
            return Err(format!("field {} is not finite ({text})", NAMES[k]));
        }
    }
    // Divide by the largest magnitude first so neither tiny nor huge components
    // under- or overflow the length.
    let m = v.iter().fold(0.0f64, |m, c| m.max(c.abs()));
    if m == 0.0 {
        return Err(format!(
            "direction ({}, {}, {}) has zero length",
            v[0], v[1], v[2]
        ));
    }
    let s = v.map(|c| c / m);
    let len = m * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
    // A direction that is already unit length to f32 precision (such as one written
    // by `sample`) is kept bit for bit: renormalising would only move its last bits.
    let u = if (len - 1.0).abs() <= UNIT_TOLERANCE {
        v.map(|c| c as f32)
    } else {
        v.map(|c| (c / len) as f32)
    };
    Ok(Vec3::new(u[0], u[1], u[2]))
}
