//! Helpers shared by the integration tests (each test file includes this module;
//! not every file uses every helper).
#![allow(dead_code)]

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

/// A fresh directory under the system temp dir, removed with its contents when
/// dropped (also on panic). Unique per process, call and time.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let dir = std::env::temp_dir().join(format!(
            "monocap-test-{tag}-{}-{}-{nanos}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        fs::create_dir_all(&dir).expect("create temp dir");
        TempDir(dir)
    }

    /// A path inside the directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    /// Writes a file inside the directory and returns its path.
    pub fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.path(name);
        fs::write(&p, bytes).expect("write temp file");
        p
    }

    /// Names of the files in the directory, sorted.
    pub fn files(&self) -> Vec<String> {
        let mut names: Vec<String> = fs::read_dir(&self.0)
            .expect("list temp dir")
            .map(|e| {
                e.expect("dir entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        names.sort();
        names
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

/// Runs the `monocap` binary built for the tests.
pub fn monocap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_monocap"))
        .args(args)
        .output()
        .expect("the monocap binary runs")
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A colour clip of a person who never moves and no person-free frame: frame 10 of
/// a clip synthesised from the fixture capture (written to `moving`), repeated 12
/// times, as the bytes of a ZIP of PNG frames.
pub fn still_person_clip(moving: &Path) -> Vec<u8> {
    let out = monocap(&[
        "synth",
        "--bvh",
        "tests/fixtures/bandai_run_normal_001_20f.bvh",
        "--out",
        s(moving),
        "--style",
        "color",
    ]);
    assert!(out.status.success(), "synth: {out:?}");
    let mut frame = Vec::new();
    let mut zip = zip::ZipArchive::new(fs::File::open(moving).unwrap()).unwrap();
    std::io::Read::read_to_end(&mut zip.by_name("000010.png").unwrap(), &mut frame).unwrap();
    let mut still = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for i in 0..12 {
        still
            .start_file(
                format!("{i:06}.png"),
                zip::write::SimpleFileOptions::default(),
            )
            .unwrap();
        std::io::Write::write_all(&mut still, &frame).unwrap();
    }
    still.finish().unwrap().into_inner()
}
