//! Rule files that are not regular files (`/dev/zero`, a FIFO, a directory) are refused by
//! name before anything is read from them. Before the fix `load_files` read `/dev/zero` until
//! memory ran out and waited forever on a FIFO without a writer.

use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

use topomech_rules::{load_files, load_files_for, Diagnostic, Severity};

/// `f()`, or a panic when it takes longer than `limit` (a hang fails instead of blocking).
fn within<T: Send + 'static>(limit: Duration, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(limit)
        .unwrap_or_else(|_| panic!("did not finish within {limit:?}"))
}

/// The single `file` error of a refused load, as `FILE:LINE:COL: error[file]: message`.
fn refusal(d: &[Diagnostic]) -> String {
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0].severity, Severity::Error);
    assert_eq!(d[0].condition, "file");
    d[0].to_string()
}

/// `/dev/zero` is an endless stream: refused at once, by name, instead of read until memory
/// runs out.
#[cfg(unix)]
#[test]
fn dev_zero_is_refused_not_read_forever() {
    let msg = within(Duration::from_secs(5), || {
        refusal(&load_files(&[Path::new("/dev/zero")]).unwrap_err())
    });
    assert!(
        msg.contains("/dev/zero:1:1") && msg.contains("not a regular file"),
        "{msg}"
    );
    let msg = within(Duration::from_secs(5), || {
        refusal(&load_files_for(3, &[Path::new("/dev/zero")]).unwrap_err())
    });
    assert!(msg.contains("not a regular file"), "{msg}");
}

/// A named pipe nobody writes to: refused instead of waited on for a writer.
#[cfg(unix)]
#[test]
fn a_fifo_is_refused_not_waited_on() {
    let dir = std::env::temp_dir().join(format!("topomech-rule-fifo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("ff.tmr");
    let _ = std::fs::remove_file(&fifo);
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        eprintln!("mkfifo unavailable: skipped");
        return;
    }
    let path = fifo.clone();
    let msg = within(Duration::from_secs(5), move || {
        refusal(&load_files(&[path.as_path()]).unwrap_err())
    });
    let _ = std::fs::remove_file(&fifo);
    let _ = std::fs::remove_dir(&dir);
    assert!(
        msg.contains("ff.tmr:1:1") && msg.contains("not a regular file"),
        "{msg}"
    );
}

/// A directory is refused the same way, with its path.
#[test]
fn a_directory_is_refused_with_its_path() {
    let dir = std::env::temp_dir();
    let msg = refusal(&load_files(&[dir.as_path()]).unwrap_err());
    assert!(msg.contains("not a regular file"), "{msg}");
    assert!(msg.contains(&dir.display().to_string()), "{msg}");
}

/// A regular file is still read (the check refuses only what is not one).
#[test]
fn a_regular_file_is_read() {
    let dir = std::env::temp_dir().join(format!("topomech-rule-file-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("ok.tmr");
    std::fs::write(&path, "dimension 2\nembedding w : f64 on <0>\n").unwrap();
    let r = load_files(&[path.as_path()]);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(r.unwrap().0.dimension(), 2);
}
