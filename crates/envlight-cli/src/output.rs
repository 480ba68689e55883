//! Where results go: buffered stdout, or an `-o FILE` written atomically.
//!
//! A file is written to a temporary file in the same directory and renamed over
//! `FILE` only by [`Output::finish`]. If the command fails first (or panics, or is
//! interrupted before finishing), the temporary file is removed and an existing
//! `FILE` is left exactly as it was: never a partial file, never a destroyed one.
//! (The data is not fsync'ed before the rename: that would guard against power loss,
//! not failures of the command, and costs as much as writing the CSV.)

use std::fs::File;
use std::io::{self, BufWriter, StdoutLock, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;
use tempfile::NamedTempFile;

/// Buffer size for both sinks: large enough that formatting, not syscalls, bounds
/// the throughput of CSV output.
const BUFFER_BYTES: usize = 1 << 20;

/// A byte sink for a command's main output.
pub struct Output {
    sink: Sink,
}

enum Sink {
    Stdout(BufWriter<StdoutLock<'static>>),
    File {
        writer: BufWriter<NamedTempFile>,
        path: PathBuf,
    },
}

impl Output {
    /// Stdout when `path` is `None` or `-`, otherwise an atomic writer for `path`.
    ///
    /// # Errors
    /// When the temporary file cannot be created next to `path` (the message names
    /// `path`).
    pub fn create(path: Option<&Path>) -> anyhow::Result<Self> {
        match path {
            None => Ok(Self::stdout()),
            Some(p) if p.as_os_str() == "-" => Ok(Self::stdout()),
            Some(p) => Self::file(p),
        }
    }

    fn stdout() -> Self {
        Self {
            sink: Sink::Stdout(BufWriter::with_capacity(BUFFER_BYTES, io::stdout().lock())),
        }
    }

    fn file(path: &Path) -> anyhow::Result<Self> {
        // Found now rather than when the finished output cannot be renamed over it.
        if path.is_dir() {
            anyhow::bail!(
                "{}: cannot write the output: it is a directory",
                path.display()
            );
        }
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".to_string());
        let prefix = format!(".{name}.");
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".partial");
        #[cfg(unix)]
        {
            // Like any newly created file: 0666 less the umask (the kernel applies it),
            // not tempfile's private 0600.
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(0o666));
        }
        let temp = builder
            .tempfile_in(dir)
            .with_context(|| format!("{}: cannot create output file", path.display()))?;
        Ok(Self {
            sink: Sink::File {
                writer: BufWriter::with_capacity(BUFFER_BYTES, temp),
                path: path.to_path_buf(),
            },
        })
    }

    /// What to call this output in messages: the path, or `<stdout>`.
    pub fn name(&self) -> String {
        match &self.sink {
            Sink::Stdout(_) => "<stdout>".to_string(),
            Sink::File { path, .. } => path.display().to_string(),
        }
    }

    /// Flushes everything and, for a file, renames it into place.
    ///
    /// # Errors
    /// A failed write, flush or rename (naming the output); a closed stdout gives an
    /// error of kind [`io::ErrorKind::BrokenPipe`], see [`is_broken_pipe`].
    pub fn finish(self) -> anyhow::Result<()> {
        let name = self.name();
        match self.sink {
            Sink::Stdout(mut w) => w.flush().with_context(|| format!("{name}: write failed")),
            Sink::File { writer, path } => {
                let temp = writer
                    .into_inner()
                    .map_err(|e| e.into_error())
                    .with_context(|| format!("{name}: write failed"))?;
                temp.persist(&path).map_err(|e| e.error).with_context(|| {
                    format!("{name}: cannot move the finished output into place")
                })?;
                Ok(())
            }
        }
    }
}

impl Write for Output {
    #[inline]
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match &mut self.sink {
            Sink::Stdout(w) => w.write(buf),
            Sink::File { writer, .. } => writer.write(buf),
        }
    }

    #[inline]
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        match &mut self.sink {
            Sink::Stdout(w) => w.write_all(buf),
            Sink::File { writer, .. } => writer.write_all(buf),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match &mut self.sink {
            Sink::Stdout(w) => w.flush(),
            Sink::File { writer, .. } => writer.flush(),
        }
    }
}

/// Writes `bytes` to `out`, naming the output in the error.
pub fn write_bytes(out: &mut Output, bytes: &[u8]) -> anyhow::Result<()> {
    out.write_all(bytes)
        .with_context(|| format!("{}: write failed", out.name()))
}

/// True when `error` comes from writing to a closed pipe (`envlight sample | head`):
/// the reader has all it wanted, so the command ends quietly with status 0.
pub fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<io::Error>()
            .is_some_and(|e| e.kind() == io::ErrorKind::BrokenPipe)
    })
}

/// Opens `path` for reading, naming it in the error.
pub fn open_input(path: &Path) -> anyhow::Result<File> {
    File::open(path).with_context(|| format!("{}: cannot open", path.display()))
}
