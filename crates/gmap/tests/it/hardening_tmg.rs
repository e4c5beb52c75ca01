//! Hardening of `.tmg` reading (issue 13): every count in a file is checked against the bytes
//! left before anything is allocated for it (no allocation bomb from a short file), and
//! `load` refuses paths that are endless streams (`/dev/zero`, a FIFO) instead of reading
//! them forever.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::io::{from_bytes, load, to_bytes, FormatError};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{EmbeddingType, OrbitType, Policy};

const MAGIC: &[u8] = b"TOPOMECH-GMAP\n";

fn u32le(w: &mut Vec<u8>, x: u32) {
    w.extend_from_slice(&x.to_le_bytes());
}

/// A file header: version 1, `dim`, `cap` live darts with every link free.
fn header(dim: u32, cap: u32) -> Vec<u8> {
    let mut w = MAGIC.to_vec();
    u32le(&mut w, 1);
    u32le(&mut w, dim);
    u32le(&mut w, cap);
    w.extend(std::iter::repeat_n(1u8, cap as usize));
    for _ in 0..4 {
        for d in 0..cap {
            u32le(&mut w, d);
        }
    }
    w
}

/// The start of one embedding record, up to and including its slot count.
fn record(w: &mut Vec<u8>, name: &str, orbit: u8, ty: (u8, u8, u8), n_slots: u32) {
    u32le(w, name.len() as u32);
    w.extend_from_slice(name.as_bytes());
    w.push(orbit);
    w.extend([ty.0, ty.1, ty.2]);
    w.push(0); // policy copy
    w.push(0); // not derived
    u32le(w, n_slots);
}

/// Runs `f` on another thread; fails when it takes more than `limit` (a reader that
/// allocates gigabytes, or blocks on a stream, does).
fn within<T: Send + 'static>(limit: Duration, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(limit)
        .unwrap_or_else(|_| panic!("did not finish within {limit:?}"))
}

/// The file: 66 bytes, one dart, one vertex embedding claiming 2^32 - 1 slots.
/// Before the fix the reader allocated a use count per claimed slot (16 GiB) before
/// noticing the values were missing.
#[test]
fn a_66_byte_file_claiming_4_billion_slots_is_refused_before_allocating() {
    let mut b = header(2, 1);
    u32le(&mut b, 1);
    record(&mut b, "x", 0b110, (0, 1, 1), u32::MAX);
    u32le(&mut b, 0); // dart 0 -> slot 0
    assert_eq!(b.len(), 66);
    let t = Instant::now();
    let err = within(Duration::from_secs(5), move || from_bytes(&b).unwrap_err());
    assert!(t.elapsed() < Duration::from_secs(5));
    let msg = err.to_string();
    assert!(matches!(err, FormatError::Corrupt { .. }), "{msg}");
    assert!(
        msg.contains("embedding 'x'") && msg.contains("4294967295 slots"),
        "the message names the embedding and its count: {msg}"
    );
    assert!(msg.contains("only 4 are left"), "{msg}");
}

/// Each count field (darts, embeddings, name length, slots of every value type, on a
/// dart-indexed and a slot-mapped orbit) set to a huge value in an otherwise short file is
/// refused quickly, with an error, never an allocation of what it claims.
#[test]
fn every_count_past_the_end_of_the_file_is_refused() {
    let huge = [u32::MAX, u32::MAX - 1, 1 << 31, 1 << 28, 1 << 20];
    let types = [
        (0, 1, 1),
        (1, 1, 1),
        (2, 1, 1),
        (3, 2, 1),
        (4, 3, 1),
        (5, 255, 255),
    ];
    let mut cases: Vec<(String, Vec<u8>)> = Vec::new();
    for &n in &huge {
        // a huge capacity (the flags and links are absent)
        let mut b = MAGIC.to_vec();
        u32le(&mut b, 1);
        u32le(&mut b, 2);
        u32le(&mut b, n);
        b.extend([1, 0, 0, 0]);
        cases.push((format!("capacity {n}"), b));
        // a huge number of embeddings
        let mut b = header(2, 1);
        u32le(&mut b, n);
        b.extend([0; 8]);
        cases.push((format!("{n} embeddings"), b));
        // a huge name length
        let mut b = header(2, 1);
        u32le(&mut b, 1);
        u32le(&mut b, n);
        b.extend(b"abc");
        cases.push((format!("a name of {n} bytes"), b));
        for ty in types {
            // slot-mapped (a vertex orbit) and dart-indexed (<>: slots = capacity)
            for orbit in [0b110u8, 0b000] {
                let mut b = header(2, 1);
                u32le(&mut b, 1);
                record(&mut b, "e", orbit, ty, n);
                u32le(&mut b, 0);
                b.extend([0; 8]);
                cases.push((format!("{n} slots of type {ty:?} on orbit {orbit:#b}"), b));
            }
        }
    }
    let n_cases = cases.len();
    let refused = within(Duration::from_secs(10), move || {
        cases
            .into_iter()
            .filter_map(|(what, b)| match from_bytes(&b) {
                Ok(_) => Some(format!("{what}: accepted")),
                Err(_) => None,
            })
            .collect::<Vec<_>>()
    });
    assert!(refused.is_empty(), "{refused:?} (of {n_cases})");
}

/// The same slot count that is refused in a short file is read when the file does hold
/// its values: the check is against the bytes left, not a fixed limit.
#[test]
fn a_slot_count_the_file_holds_is_still_read() {
    let mut b = header(2, 1);
    u32le(&mut b, 1);
    record(&mut b, "x", 0b110, (0, 1, 1), 3);
    u32le(&mut b, 2); // dart 0 -> slot 2; slots 0 and 1 free
    for v in [1.5f64, 2.5, 3.5] {
        b.extend_from_slice(&v.to_bits().to_le_bytes());
    }
    let g = from_bytes(&b).unwrap();
    assert_eq!(to_bytes(&g), b);
    let x = g.require("x").unwrap();
    assert_eq!(g.real(x, topomech_gmap::Dart(0)), [3.5]);
    // one byte short of the values: refused with the count
    let err = from_bytes(&b[..b.len() - 1]).unwrap_err().to_string();
    assert!(err.contains("3 slots of 8 bytes"), "{err}");
}

/// Deterministic mutations (fixed seed) of a map with every kind of embedding, biased
/// towards the count fields: no panic, and each one answers fast.
#[test]
fn mutated_maps_with_every_embedding_kind_never_panic_or_stall() {
    let (mut g, _) = build(
        &grid([3, 2], [1.0, 1.0], GridElement::Mixed),
        &BuildOptions::default(),
    )
    .unwrap();
    let o = |s: &str| OrbitType::parse(s).unwrap();
    g.add_embedding("flag", EmbeddingType::Bool, o("<>"), Policy::Copy)
        .unwrap();
    g.add_embedding("k", EmbeddingType::Vec2, o("<0>"), Policy::Mean)
        .unwrap();
    g.add_embedding(
        "m",
        EmbeddingType::Mat { rows: 2, cols: 2 },
        o("<0,1>"),
        Policy::Copy,
    )
    .unwrap();
    g.add_embedding("id", EmbeddingType::I64, o("<0,1>"), Policy::Error)
        .unwrap();
    let base = to_bytes(&g);
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        // xorshift64*
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        state.wrapping_mul(0x2545_f491_4f6c_dd1d)
    };
    let mut inputs = Vec::new();
    for _ in 0..3000 {
        let mut b = base.clone();
        match next() % 4 {
            0 => {
                // flip a few bytes anywhere
                for _ in 0..=(next() % 4) {
                    let k = (next() as usize) % b.len();
                    b[k] = next() as u8;
                }
            }
            1 => {
                // write a huge u32 at a random aligned-or-not offset
                let k = (next() as usize) % (b.len() - 4);
                let x = [u32::MAX, 1 << 31, 1 << 24, 0][(next() % 4) as usize];
                b[k..k + 4].copy_from_slice(&x.to_le_bytes());
            }
            2 => {
                let n = (next() as usize) % b.len();
                b.truncate(n);
            }
            _ => {
                let k = (next() as usize) % b.len();
                let n = (next() as usize) % 16;
                b.drain(k..(k + n).min(b.len()));
            }
        }
        inputs.push(b);
    }
    let (ok, err) = within(Duration::from_secs(20), move || {
        let (mut ok, mut err) = (0, 0);
        for b in inputs {
            match from_bytes(&b) {
                Ok(h) => {
                    ok += 1;
                    let _ = h.validate();
                    let _ = h.cell_counts();
                }
                Err(_) => err += 1,
            }
        }
        (ok, err)
    });
    assert_eq!(ok + err, 3000);
    assert!(err > 1000, "most mutations are refused ({err} of 3000)");
}

/// `/dev/zero` is an endless stream: `load` refuses it (it is not a regular file) at once,
/// instead of reading until memory runs out.
#[cfg(unix)]
#[test]
fn loading_dev_zero_is_refused_not_read_forever() {
    let err = within(Duration::from_secs(5), || {
        load(std::path::Path::new("/dev/zero")).unwrap_err()
    });
    let msg = err.to_string();
    assert!(matches!(err, FormatError::Io { .. }), "{msg}");
    assert!(
        msg.contains("/dev/zero") && msg.contains("not a regular file"),
        "{msg}"
    );
}

/// A named pipe nobody writes to: `load` refuses it instead of waiting forever for a writer.
#[cfg(unix)]
#[test]
fn loading_a_fifo_is_refused_not_waited_on() {
    let dir = std::env::temp_dir().join(format!("topomech-fifo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("map.tmg");
    let _ = std::fs::remove_file(&fifo);
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        eprintln!("mkfifo unavailable: skipped");
        return;
    }
    let path = fifo.clone();
    let msg = within(Duration::from_secs(5), move || {
        load(&path).unwrap_err().to_string()
    });
    let _ = std::fs::remove_file(&fifo);
    let _ = std::fs::remove_dir(&dir);
    assert!(
        msg.contains("map.tmg") && msg.contains("not a regular file"),
        "{msg}"
    );
}

/// A directory is refused the same way, with its path.
#[test]
fn loading_a_directory_is_refused_with_its_path() {
    let dir = std::env::temp_dir();
    let msg = load(&dir).unwrap_err().to_string();
    assert!(msg.contains("not a regular file"), "{msg}");
    assert!(msg.contains(&dir.display().to_string()), "{msg}");
}
