//! A command per capture (`--camera cmd:'grab --out {path}'`): runs the command with `{path}`
//! replaced by a fresh file path, waits up to the deadline (then kills it and everything it
//! started), and reads the image it wrote. The command line is split into words like a shell
//! does (quotes, backslashes) but is not run by a shell: write `sh -c '…'` for pipes.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant, SystemTime};

use perception::FrameImage;

use super::{CameraError, CameraSource, Capture, MTIME_SLACK, Sensor, age_before, decode_file};

/// The placeholder replaced by the image path in the command's words.
pub const PATH_PLACEHOLDER: &str = "{path}";

/// How many bytes of a command's standard error an error message keeps (the end).
const STDERR_TAIL: usize = 600;

/// How long a finished or killed command's standard error is awaited.
const STDERR_WAIT: Duration = Duration::from_millis(300);

/// A command that grabs one image per run.
#[derive(Debug)]
pub struct CommandCamera {
    command: String,
    words: Vec<String>,
    dir: tempfile::TempDir,
    count: u64,
    last: Option<PathBuf>,
    sensor: Sensor,
}

impl CommandCamera {
    /// Checks `command` (its words split, `{path}` present, its program found) for images of
    /// `sensor`'s size.
    pub fn open(command: &str, sensor: Sensor) -> Result<Self, CameraError> {
        let invalid = |reason: String| CameraError::Invalid {
            spec: format!("cmd:{command}"),
            reason,
        };
        let words = split_words(command).map_err(&invalid)?;
        let Some(program) = words.first() else {
            return Err(invalid("the command is empty".into()));
        };
        if !words.iter().any(|w| w.contains(PATH_PLACEHOLDER)) {
            return Err(invalid(format!(
                "the command must name the image it writes as {PATH_PLACEHOLDER}"
            )));
        }
        find_program(program).map_err(invalid)?;
        let dir = tempfile::Builder::new()
            .prefix("cell-camera-")
            .tempdir()
            .map_err(|e| invalid(format!("creating a folder for the images: {e}")))?;
        Ok(Self {
            command: command.into(),
            words,
            dir,
            count: 0,
            last: None,
            sensor,
        })
    }
}

impl CameraSource for CommandCamera {
    fn capture(&mut self, deadline: Duration) -> Result<Capture, CameraError> {
        let start = Instant::now();
        let request = SystemTime::now();
        // Only the latest image is kept.
        if let Some(old) = self.last.take() {
            let _ = std::fs::remove_file(old);
        }
        self.count += 1;
        let path = self
            .dir
            .path()
            .join(format!("capture-{:06}.png", self.count));
        let path_text = path.to_string_lossy();
        let words: Vec<String> = self
            .words
            .iter()
            .map(|w| w.replace(PATH_PLACEHOLDER, &path_text))
            .collect();
        let shown = words.join(" ");
        let failed = |status: String, stderr: String| CameraError::CommandFailed {
            command: shown.clone(),
            status,
            stderr,
        };
        let mut cmd = Command::new(&words[0]);
        cmd.args(&words[1..])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        // Its own process group, so a timeout kills whatever it started too.
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        let mut child = cmd
            .spawn()
            .map_err(|e| failed(format!("could not start: {e}"), String::new()))?;
        // Read on a thread so a chatty command never blocks on a full pipe; a process it left
        // running may hold the pipe open, so the tail is awaited only briefly.
        let stderr = child.stderr.take().map(|mut s| {
            let (tx, rx) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                let mut buf = Vec::new();
                let _ = s.read_to_end(&mut buf);
                let _ = tx.send(buf);
            });
            rx
        });
        let tail_of_stderr = |rx: Option<std::sync::mpsc::Receiver<Vec<u8>>>| {
            rx.and_then(|rx| rx.recv_timeout(STDERR_WAIT).ok())
                .map(tail_of)
                .unwrap_or_default()
        };
        let status = loop {
            match child.try_wait() {
                Ok(Some(status)) => break status,
                Ok(None) if start.elapsed() < deadline => {
                    std::thread::sleep(Duration::from_millis(5));
                }
                Ok(None) => {
                    kill_group(&mut child);
                    return Err(CameraError::CommandHung {
                        command: shown,
                        waited: deadline,
                        stderr: tail_of_stderr(stderr),
                    });
                }
                Err(e) => {
                    kill_group(&mut child);
                    return Err(failed(format!("waiting for it: {e}"), String::new()));
                }
            }
        };
        let tail = tail_of_stderr(stderr);
        if !status.success() {
            return Err(failed(status.to_string(), tail));
        }
        let taken = match std::fs::metadata(&path).and_then(|m| m.modified()) {
            Ok(t) => t,
            Err(e) => {
                return Err(failed(
                    format!("exited 0 but wrote no image at {}: {e}", path.display()),
                    tail,
                ));
            }
        };
        self.last = Some(path.clone());
        let age = age_before(taken, request);
        if age > MTIME_SLACK {
            return Err(CameraError::Stale { path, age });
        }
        let pixels = decode_file(&path, self.sensor)?;
        Ok(Capture {
            image: FrameImage::full(pixels),
            path: Some(path),
            taken,
        })
    }

    fn describe(&self) -> String {
        format!("camera command `{}`", self.command)
    }
}

/// Kills `child`'s process group (it leads one), then reaps it.
fn kill_group(child: &mut Child) {
    let group = format!("-{}", child.id());
    // `kill` is in every POSIX system; the direct kill below covers its absence.
    let _ = Command::new("kill")
        .args(["-KILL", "--", &group])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    let _ = child.kill();
    let _ = child.wait();
}

/// The last [`STDERR_TAIL`] bytes of `bytes`, as text.
fn tail_of(bytes: Vec<u8>) -> String {
    let start = bytes.len().saturating_sub(STDERR_TAIL);
    let text = String::from_utf8_lossy(&bytes[start..]).trim().to_string();
    if start > 0 {
        format!("…{text}")
    } else {
        text
    }
}

/// Finds `program` as a shell would: a path when it holds a `/`, else on `PATH`; it must be an
/// executable file.
pub fn find_program(program: &str) -> Result<PathBuf, String> {
    use std::os::unix::fs::PermissionsExt;
    let executable = |p: &Path| {
        std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
    };
    if program.contains('/') {
        let p = PathBuf::from(program);
        return if executable(&p) {
            Ok(p)
        } else if p.exists() {
            Err(format!("{program} is not an executable file"))
        } else {
            Err(format!("program {program} does not exist"))
        };
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|d| d.join(program))
        .find(|p| executable(p))
        .ok_or_else(|| format!("program {program:?} is not found on PATH"))
}

/// Splits a command line into words: whitespace separates, '…' quotes literally, "…" quotes
/// with \" and \\ escapes, a backslash outside quotes escapes the next character.
pub fn split_words(line: &str) -> Result<Vec<String>, String> {
    let mut words = Vec::new();
    let mut word: Option<String> = None;
    let mut chars = line.char_indices();
    while let Some((i, c)) = chars.next() {
        match c {
            c if c.is_whitespace() => words.extend(word.take()),
            '\'' => {
                let w = word.get_or_insert_with(String::new);
                loop {
                    match chars.next() {
                        Some((_, '\'')) => break,
                        Some((_, c)) => w.push(c),
                        None => return Err(format!("unclosed ' at column {}", i + 1)),
                    }
                }
            }
            '"' => {
                let w = word.get_or_insert_with(String::new);
                loop {
                    match chars.next() {
                        Some((_, '"')) => break,
                        Some((_, '\\')) => match chars.next() {
                            Some((_, c @ ('"' | '\\'))) => w.push(c),
                            Some((_, c)) => {
                                w.push('\\');
                                w.push(c);
                            }
                            None => return Err(format!("unclosed \" at column {}", i + 1)),
                        },
                        Some((_, c)) => w.push(c),
                        None => return Err(format!("unclosed \" at column {}", i + 1)),
                    }
                }
            }
            '\\' => match chars.next() {
                Some((_, c)) => word.get_or_insert_with(String::new).push(c),
                None => return Err(format!("a trailing \\ at column {}", i + 1)),
            },
            c => word.get_or_insert_with(String::new).push(c),
        }
    }
    words.extend(word);
    Ok(words)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_lines_split_like_a_shell() {
        assert_eq!(
            split_words(r#"grab --out {path}  -x 'a b' "c \"d\"" e\ f ''"#).unwrap(),
            ["grab", "--out", "{path}", "-x", "a b", "c \"d\"", "e f", ""]
        );
        assert!(split_words("grab 'open").unwrap_err().contains("column 6"));
        assert!(split_words("grab \"open").is_err());
        assert!(split_words("grab \\").is_err());
        assert_eq!(split_words("  ").unwrap(), Vec::<String>::new());
    }

    #[test]
    fn programs_are_found_on_path_or_refused() {
        assert!(find_program("sh").is_ok());
        let e = find_program("no-such-grab-tool-3141").unwrap_err();
        assert!(e.contains("not found on PATH"), "{e}");
        let e = find_program("/no/such/grab").unwrap_err();
        assert!(e.contains("does not exist"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let plain = dir.path().join("grab");
        std::fs::write(&plain, b"#!/bin/sh\n").unwrap();
        let e = find_program(plain.to_str().unwrap()).unwrap_err();
        assert!(e.contains("not an executable"), "{e}");
    }

    #[test]
    fn commands_without_the_path_or_program_are_refused() {
        let sensor = Sensor {
            width: 1,
            height: 1,
        };
        let e = CommandCamera::open("cp a.png b.png", sensor).unwrap_err();
        assert!(e.to_string().contains("{path}"), "{e}");
        let e = CommandCamera::open("no-such-grab-tool-3141 {path}", sensor).unwrap_err();
        assert!(e.to_string().contains("not found on PATH"), "{e}");
        assert!(CommandCamera::open("'", sensor).is_err());
    }
}
