//! Hostile `.npz` archives, made here (none is shipped): sizes that lie, deflate bombs and
//! arrays that are not trajectories. Each is refused with the file and the reason, without
//! a panic, and the memory the reader takes is measured by a counting allocator: what the
//! archive's own header declares, never what a lying size field asks for.
//!
//! One test in its own binary, so that the allocator counts this reader alone.

#[path = "../common/mod.rs"]
mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use doma::DomaError;
use doma::data::npy::{encode_npy, read_npz_trajectories};

/// Raw deflate (what a zip member holds), through flate2.
fn deflate_runs(data: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut e = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::best());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

struct Counting;

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator; the counters are plain atomics.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let now = CURRENT.fetch_add(layout.size(), Ordering::SeqCst) + layout.size();
        PEAK.fetch_max(now, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        CURRENT.fetch_sub(layout.size(), Ordering::SeqCst);
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Runs `f` and returns its result with the peak of live bytes it added.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = CURRENT.load(Ordering::SeqCst);
    PEAK.store(base, Ordering::SeqCst);
    let out = f();
    (out, PEAK.load(Ordering::SeqCst) - base)
}

const MB: usize = 1 << 20;

/// A one-member zip archive: `data` (stored, or already deflated) under `name`, whose
/// directory declares `size` inflated bytes and `crc`; sizes go in a zip64 extra field.
fn zip(name: &str, deflated: bool, data: &[u8], size: u64, crc: u32) -> Vec<u8> {
    let method: u16 = if deflated { 8 } else { 0 };
    let mut out = Vec::new();
    // Local header: sizes saturated, the real ones in the central directory's zip64 field.
    out.extend_from_slice(&0x0403_4b50u32.to_le_bytes());
    out.extend_from_slice(&[45, 0, 0, 0]);
    out.extend_from_slice(&method.to_le_bytes());
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&crc.to_le_bytes());
    out.extend_from_slice(&[0xFF; 8]);
    out.extend_from_slice(&(name.len() as u16).to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out.extend_from_slice(name.as_bytes());
    out.extend_from_slice(data);
    let dir = out.len();
    out.extend_from_slice(&0x0201_4b50u32.to_le_bytes());
    out.extend_from_slice(&[45, 0, 45, 0, 0, 0]);
    out.extend_from_slice(&method.to_le_bytes());
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&crc.to_le_bytes());
    out.extend_from_slice(&[0xFF; 8]);
    out.extend_from_slice(&(name.len() as u16).to_le_bytes());
    out.extend_from_slice(&20u16.to_le_bytes()); // extra: 4 + 2 × 8
    out.extend_from_slice(&[0; 10]); // comment, disk, attributes
    out.extend_from_slice(&0u32.to_le_bytes()); // local header at 0
    out.extend_from_slice(name.as_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&16u16.to_le_bytes());
    out.extend_from_slice(&size.to_le_bytes());
    out.extend_from_slice(&(data.len() as u64).to_le_bytes());
    let dir_len = out.len() - dir;
    out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&(dir_len as u32).to_le_bytes());
    out.extend_from_slice(&(dir as u32).to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out
}

/// The `.npy` bytes of `count` zero `f8` values of `shape`.
fn zeros_npy(shape: &str, count: usize) -> Vec<u8> {
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.resize(out.len() + 8 * count, 0);
    out
}

fn refused(path: &Path, what: &str) -> (String, usize) {
    let (result, peak) = peak_of(|| read_npz_trajectories(path, None));
    match result {
        Err(DomaError::Malformed { path: p, reason }) => {
            assert_eq!(p, path, "{what}: the error names another file");
            (reason, peak)
        }
        other => panic!("{what}: expected a refusal, got {other:?}"),
    }
}

#[test]
fn hostile_npz_archives_are_refused_within_a_bounded_memory() {
    let dir = common::scratch("doma-bombs");
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let small = encode_npy(&[2, 4, 3], &[0.5; 24]);
    let crc = doma_formats::crc32(&small);

    // 1. A stored member whose zip64 size says 1 TiB, and one whose size is 2⁶³ or more.
    for (i, size) in [1u64 << 40, 1 << 63, u64::MAX].into_iter().enumerate() {
        let path = write(
            &format!("huge{i}.npz"),
            &zip("a.npy", false, &small, size, crc),
        );
        let (reason, peak) = refused(&path, "a lying stored size");
        assert!(reason.contains("member a"), "{reason}");
        assert!(peak < MB, "a lying size cost {peak} bytes");
    }

    // 2. A deflated member that declares 1 TiB from 1 KB: more than deflate can hold.
    let path = write(
        "ratio.npz",
        &zip("a.npy", true, &deflate_runs(&small), 1 << 40, crc),
    );
    let (reason, peak) = refused(&path, "an impossible ratio");
    assert!(reason.contains("more than deflate can"), "{reason}");
    assert!(peak < MB, "{peak}");

    // 3. A 64 MB deflate bomb that is no trajectory array (shape (8388608,)): refused from
    //    its header, before its values are inflated.
    let npy = zeros_npy("(8388608,)", 8 << 20);
    let bomb = deflate_runs(&npy);
    let (size, crc_bomb) = (npy.len() as u64, doma_formats::crc32(&npy));
    drop(npy);
    let path = write("shape.npz", &zip("a.npy", true, &bomb, size, crc_bomb));
    let (reason, peak) = refused(&path, "a bomb of the wrong shape");
    assert!(reason.contains("not [T, N, 3]"), "{reason}");
    assert!(
        peak < bomb.len() + MB,
        "{peak} bytes for a {} byte file",
        bomb.len()
    );

    // 4. The same stream under a directory that says 1 KB: the header and the directory
    //    disagree, and nothing past the header is inflated.
    let path = write("lie.npz", &zip("a.npy", true, &bomb, 1024, crc_bomb));
    let (reason, peak) = refused(&path, "a directory smaller than the header");
    assert!(reason.contains("zip directory"), "{reason}");
    assert!(peak < bomb.len() + MB, "{peak}");

    // 5. A valid 48 MB [T, N, 3] f8 member of zeros (a legitimate ~300 KB file): read, and
    //    the memory is the f32 array it declares (24 MB), not the f8 bytes or copies.
    let (t, n) = (100, 20_000);
    let npy = zeros_npy(&format!("({t}, {n}, 3)"), t * n * 3);
    let (size, crc_ok) = (npy.len() as u64, doma_formats::crc32(&npy));
    let packed = deflate_runs(&npy);
    drop(npy);
    let path = write("valid.npz", &zip("points.npy", true, &packed, size, crc_ok));
    let (result, peak) = peak_of(|| read_npz_trajectories(&path, None));
    let traj = result.unwrap();
    assert_eq!((traj.frames(), traj.points()), (t, n));
    let array = 4 * t * n * 3;
    assert!(
        peak < array + packed.len() + 2 * MB,
        "{peak} bytes to read a {array} byte f32 array"
    );
    eprintln!(
        "valid {} KB archive of a {} MB f32 array: peak {:.1} MB",
        packed.len() / 1024,
        array / MB,
        peak as f64 / MB as f64
    );
}
