//! A deterministic fuzz test of the bundle reader, in the normal suite.
//!
//! About 20,000 cases from fixed seeds: random files, mutations of valid raw
//! and zstd bundles (bit flips, byte overwrites, truncations, extensions, table
//! fields changed under a recomputed header CRC, section contents changed under
//! recomputed CRCs, sections dropped, renamed, reordered or added), and every
//! single-bit flip of a small all-zstd bundle. For each case:
//! - the reader returns `Ok` or `Err`; a panic fails the test (no `catch_unwind`);
//! - no single allocation exceeds a small multiple of the input, so no count in
//!   the bytes was trusted before it was checked against them;
//! - what it accepts re-encodes and decodes to the same value;
//! - corruption without recomputed CRCs is always refused.
//!
//! A hand-rolled xorshift rather than `proptest`: the cases are byte-level
//! mutations that shrinking would not make clearer, a failure names its kind
//! and case number (replayable from the seed), and there is no dependency.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::fmt;
use std::time::Instant;

use super::container::write_container;
use super::tests::{
    get_u32, get_u64, header_crc, random_mesh, random_sun, random_transfer, raw_sections, set_u32, small_regular_bundle, small_zstd_bytes,
    tiny_bundle, Rng,
};
use super::*;

// ---------------------------------------------------------------- allocation watch

thread_local! {
    /// The largest single allocation (or reallocation) this thread asked for since the last reset.
    static LARGEST_REQUEST: Cell<usize> = const { Cell::new(0) };
}

/// The system allocator, noting request sizes per thread. Tests run on several
/// threads at once; a thread-local keeps each fuzz case's figure its own.
struct WatchingAllocator;

fn note_request(size: usize) {
    // `try_with`: allocations can happen while the thread's locals are torn down.
    let _ = LARGEST_REQUEST.try_with(|largest| largest.set(largest.get().max(size)));
}

unsafe impl GlobalAlloc for WatchingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_request(layout.size());
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_request(layout.size());
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_request(new_size);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: WatchingAllocator = WatchingAllocator;

/// Forgets the largest allocation this thread asked for (other fuzz tests in the crate share the watch).
pub(crate) fn reset_largest_allocation() {
    LARGEST_REQUEST.with(|l| l.set(0));
}

/// The largest allocation this thread asked for since [`reset_largest_allocation`].
pub(crate) fn largest_allocation() -> usize {
    LARGEST_REQUEST.with(Cell::get)
}

/// The most one allocation may take while decoding `input_len` bytes. Decoding
/// legitimately expands data (zstd, f16 → f32, tinted → C·n² values), so the
/// bound is generous (the largest seen is 18 KB, for inputs of at most 3.5 KB);
/// what it catches is a forged count turning into an allocation before the
/// bytes were checked. (Counts near 2³² abort on allocation failure, which
/// fails the run all the same.)
fn allocation_allowance(input_len: usize) -> usize {
    64 * input_len + (64 << 10)
}

// ---------------------------------------------------------------- bases

/// A valid bundle to mutate: its value, its bytes and its sections' raw bytes.
struct Base {
    bytes: Vec<u8>,
    parts: Vec<([u8; 4], Vec<u8>)>,
    options: EncodeOptions,
}

fn fuzz_bundle(seed: u64, quantization: Quantization) -> Bundle {
    let mut rng = Rng(seed);
    let (vertices, triangles) = (8, 6);
    Bundle {
        meta: serde_json::json!({"tool": "fuzz", "seed": seed, "stats": {"max_error": 0.25}}),
        mesh: random_mesh(&mut rng, vertices, triangles),
        transfer: Some(random_transfer(&mut rng, vertices, quantization)),
        sun: Some(random_sun(&mut rng, vertices, 5)),
        texels: None,
    }
}

fn base(bundle: Bundle, options: EncodeOptions) -> Base {
    let bytes = encode_bundle_with(&bundle, options).unwrap();
    assert!(decode_bundle(&bytes).is_ok(), "a fuzz base must be valid");
    Base { bytes, parts: raw_sections(&bundle), options }
}

/// Raw and zstd bundles of every quantization, a minimal one, an all-zstd
/// one and a texel one with the sun on an atlas of its own.
fn bases() -> Vec<Base> {
    let raw = EncodeOptions { compression: Compression::None };
    let zstd = EncodeOptions::default();
    vec![
        base(tiny_bundle(), raw),
        base(small_regular_bundle(), zstd),
        base(fuzz_bundle(1, Quantization::F32), raw),
        base(fuzz_bundle(2, Quantization::F16), zstd),
        base(fuzz_bundle(3, Quantization::I16PerVertexScale), zstd),
        base(fuzz_bundle(4, Quantization::F16Tinted), raw),
        base(fuzz_bundle(5, Quantization::I16PerVertexScale), raw),
        base(fuzz_bundle(6, Quantization::F16Tinted), zstd),
        base(super::tests::sun_atlas_bundle(), zstd),
    ]
}

// ---------------------------------------------------------------- mutations

/// Values that tend to break count and offset arithmetic.
fn interesting_u64(rng: &mut Rng, current: u64) -> u64 {
    match rng.below(12) {
        0 => 0,
        1 => 1,
        2 => current.wrapping_add(1),
        3 => current.wrapping_sub(1),
        4 => current.wrapping_add(8),
        5 => current.wrapping_sub(8),
        6 => current.wrapping_mul(2),
        7 => u32::MAX as u64,
        8 => u64::MAX,
        9 => 1 << 31,
        10 => 1 << 32,
        _ => rng.next(),
    }
}

fn random_bytes(rng: &mut Rng, n: usize) -> Vec<u8> {
    (0..n).map(|_| rng.next() as u8).collect()
}

/// Recomputes the header CRC when the table lies within the bytes.
fn seal_header(bytes: &mut [u8]) {
    let table_end = HEADER_LEN as u64 + get_u32(bytes, 12) as u64 * ENTRY_LEN as u64;
    if bytes.len() >= HEADER_LEN && table_end <= bytes.len() as u64 {
        let crc = header_crc(bytes);
        set_u32(bytes, 28, crc);
    }
}

fn flip_bits(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for _ in 0..1 + rng.below(4) {
        let bit = rng.below(out.len() * 8);
        out[bit / 8] ^= 1 << (bit % 8);
    }
    out
}

fn overwrite_bytes(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(out.len());
        out[at] = [0x00, 0xff, rng.next() as u8][rng.below(3)];
    }
    out
}

fn truncate(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    bytes[..rng.below(bytes.len())].to_vec()
}

/// Appends bytes; half the time the header's total length follows (sealed), so
/// the layout checks rather than the length check see the extra bytes.
fn extend(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let extra = 1 + rng.below(64);
    let mut out = bytes.to_vec();
    let tail = if rng.below(2) == 0 { vec![0; extra] } else { random_bytes(rng, extra) };
    out.extend_from_slice(&tail);
    if rng.below(2) == 0 {
        let total_length = out.len() as u64;
        out[16..24].copy_from_slice(&total_length.to_le_bytes());
        seal_header(&mut out);
    }
    out
}

/// Changes one header or table field and recomputes the header CRC, so the
/// layout, codec and section checks behind it are reached.
fn change_table_field(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    let sections = get_u32(&out, 12) as usize;
    // (offset, width): header minor, section_count, total_length, flags; or an entry field.
    let (at, width) = if rng.below(4) == 0 || sections == 0 {
        [(10, 2), (12, 4), (16, 8), (24, 4)][rng.below(4)]
    } else {
        let entry = HEADER_LEN + rng.below(sections) * ENTRY_LEN;
        let (field, width) = [(0, 1), (4, 4), (8, 8), (16, 8), (24, 8), (32, 4), (36, 4)][rng.below(7)];
        let field = if field == 0 { rng.below(4) } else { field }; // one tag byte
        (entry + field, width)
    };
    let current = match width {
        1 => out[at] as u64,
        2 => u16::from_le_bytes([out[at], out[at + 1]]) as u64,
        4 => get_u32(&out, at) as u64,
        _ => get_u64(&out, at),
    };
    let value = interesting_u64(rng, current).to_le_bytes();
    out[at..at + width].copy_from_slice(&value[..width]);
    seal_header(&mut out);
    out
}

/// One change inside a section's raw bytes: a bit, a byte, an aligned u32 set
/// to a count-breaking value, bytes inserted or removed.
fn mutate_raw(rng: &mut Rng, raw: &mut Vec<u8>) {
    let len = raw.len();
    match rng.below(6) {
        0 if len > 0 => raw[rng.below(len)] ^= 1 << rng.below(8),
        1 if len > 0 => raw[rng.below(len)] = rng.next() as u8,
        2 if len >= 4 => {
            let at = rng.below(len / 4) * 4;
            let value = interesting_u64(rng, get_u32(raw, at) as u64) as u32;
            set_u32(raw, at, value);
        }
        3 => {
            let at = rng.below(len + 1);
            let n = 1 + rng.below(8);
            raw.splice(at..at, random_bytes(rng, n));
        }
        4 if len > 0 => {
            let at = rng.below(len);
            let n = (1 + rng.below(8)).min(len - at);
            raw.drain(at..at + n);
        }
        _ => raw.truncate(rng.below(len + 1)),
    }
}

/// Section contents changed, then laid out by the container writer: every CRC
/// is valid, so the section decoders themselves see the hostile bytes.
fn mutate_content(rng: &mut Rng, base: &Base) -> Vec<u8> {
    let mut parts = base.parts.clone();
    for _ in 0..1 + rng.below(3) {
        let i = rng.below(parts.len());
        mutate_raw(rng, &mut parts[i].1);
    }
    write_container(&parts, base.options).unwrap()
}

/// Sections dropped, renamed, swapped or added (valid container, CRCs and all).
fn reshape_sections(rng: &mut Rng, base: &Base) -> Vec<u8> {
    let mut parts = base.parts.clone();
    let i = rng.below(parts.len());
    match rng.below(4) {
        0 => {
            parts.remove(i);
        }
        1 => parts[i].0[rng.below(4)] = b'!' + rng.below(94) as u8,
        2 => {
            let j = rng.below(parts.len());
            parts.swap(i, j);
        }
        _ => {
            let n = rng.below(64);
            parts.insert(i, (*b"zFUZ", random_bytes(rng, n)));
        }
    }
    // A rename can repeat a tag, which the writer refuses: then keep the file as it was.
    write_container(&parts, base.options).unwrap_or_else(|_| base.bytes.clone())
}

/// Random bytes; some with the magic and version, some with a sealed random
/// table, so each layer of the parser gets hostile input.
fn random_file(rng: &mut Rng, valid: &[u8]) -> Vec<u8> {
    let len = rng.below(600);
    let mut bytes = random_bytes(rng, len);
    match rng.below(3) {
        0 => {}
        1 => {
            let keep = len.min(12);
            bytes[..keep].copy_from_slice(&valid[..keep]);
        }
        _ if len >= HEADER_LEN => {
            bytes[..12].copy_from_slice(&valid[..12]);
            let sections = rng.below(((len - HEADER_LEN) / ENTRY_LEN).min(4) + 1);
            set_u32(&mut bytes, 12, sections as u32);
            bytes[16..24].copy_from_slice(&(len as u64).to_le_bytes());
            seal_header(&mut bytes);
        }
        _ => {}
    }
    bytes
}

// ---------------------------------------------------------------- the oracle

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    RandomFile,
    BitFlips,
    ByteOverwrites,
    Truncation,
    Extension,
    TableField,
    Content,
    Sections,
    EveryBitFlip,
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(&format!("{self:?}"))
    }
}

impl Kind {
    /// Corruption no CRC was recomputed for: a 1.1 reader must refuse it all.
    fn must_be_refused(self) -> bool {
        matches!(self, Kind::BitFlips | Kind::ByteOverwrites | Kind::Truncation | Kind::Extension | Kind::EveryBitFlip)
    }
}

#[derive(Default)]
struct Tally {
    cases: usize,
    accepted: usize,
    largest_allocation: usize,
}

/// The same content with transfer storage whose decode → encode is exact: f32
/// and f16 as they are; i16 and f16-tinted re-derive their scales and tints
/// on encoding, so their own round trip is lossy by design and f32 stands in.
fn lossless_twin(b: &Bundle) -> Bundle {
    let mut twin = b.clone();
    if let Some(t) = &mut twin.transfer {
        if matches!(t.quantization, Quantization::I16PerVertexScale | Quantization::F16Tinted) {
            t.quantization = Quantization::F32;
        }
    }
    twin
}

/// Runs one case: no panic, no outsized allocation, refusals where corruption
/// was not resealed, and whatever is accepted re-encodes to the same value.
fn run_case(kind: Kind, case: usize, bytes: &[u8], unchanged: bool, tally: &mut Tally) {
    LARGEST_REQUEST.with(|l| l.set(0));
    let result = decode_bundle(bytes);
    let _ = list_sections(bytes);
    let largest = LARGEST_REQUEST.with(Cell::get);
    let context = || format!("{kind} case {case} ({} bytes)", bytes.len());
    assert!(largest <= allocation_allowance(bytes.len()), "{}: one allocation of {largest} bytes", context());
    tally.cases += 1;
    tally.largest_allocation = tally.largest_allocation.max(largest);
    let Ok(decoded) = result else { return };
    tally.accepted += 1;
    assert!(unchanged || !kind.must_be_refused(), "{}: corrupted bytes were accepted", context());
    let twin = lossless_twin(&decoded);
    let encoded = encode_bundle(&twin).unwrap_or_else(|e| panic!("{}: an accepted bundle does not re-encode: {e}", context()));
    let again = decode_bundle(&encoded).unwrap_or_else(|e| panic!("{}: its re-encoding does not decode: {e}", context()));
    assert!(again == twin, "{}: the re-encoded bundle decodes to another value", context());
}

/// A generator of its own per (kind, case), so any failing case replays alone.
fn case_rng(kind: Kind, case: usize) -> Rng {
    let mut z = (kind as u64) << 32 ^ case as u64 ^ 0x9e37_79b9_7f4a_7c15;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    Rng((z ^ (z >> 31)) | 1)
}

const CASES_PER_KIND: usize = 2_000;

#[test]
fn fuzz_the_bundle_reader() {
    let start = Instant::now();
    let bases = bases();
    let mut tallies: Vec<(Kind, Tally)> = Vec::new();
    let mutated = [
        Kind::RandomFile,
        Kind::BitFlips,
        Kind::ByteOverwrites,
        Kind::Truncation,
        Kind::Extension,
        Kind::TableField,
        Kind::Content,
        Kind::Sections,
    ];
    for kind in mutated {
        let mut tally = Tally::default();
        for case in 0..CASES_PER_KIND {
            let mut rng = case_rng(kind, case);
            let base = &bases[rng.below(bases.len())];
            let bytes = match kind {
                Kind::RandomFile => random_file(&mut rng, &base.bytes),
                Kind::BitFlips => flip_bits(&mut rng, &base.bytes),
                Kind::ByteOverwrites => overwrite_bytes(&mut rng, &base.bytes),
                Kind::Truncation => truncate(&mut rng, &base.bytes),
                Kind::Extension => extend(&mut rng, &base.bytes),
                Kind::TableField => change_table_field(&mut rng, &base.bytes),
                Kind::Content => mutate_content(&mut rng, base),
                Kind::Sections => reshape_sections(&mut rng, base),
                Kind::EveryBitFlip => unreachable!(),
            };
            run_case(kind, case, &bytes, bytes == base.bytes, &mut tally);
        }
        tallies.push((kind, tally));
    }

    let small = small_zstd_bytes();
    let mut tally = Tally::default();
    for bit in 0..small.len() * 8 {
        let mut flipped = small.clone();
        flipped[bit / 8] ^= 1 << (bit % 8);
        run_case(Kind::EveryBitFlip, bit, &flipped, false, &mut tally);
    }
    tallies.push((Kind::EveryBitFlip, tally));

    let total: usize = tallies.iter().map(|(_, t)| t.cases).sum();
    for (kind, t) in &tallies {
        eprintln!("fuzz {kind:>14}: {:>5} cases, {:>4} accepted, largest allocation {} bytes", t.cases, t.accepted, t.largest_allocation);
    }
    let sizes: Vec<usize> = bases.iter().map(|b| b.bytes.len()).collect();
    eprintln!("fuzz: {total} cases on bases of {sizes:?} bytes in {:.2} s", start.elapsed().as_secs_f64());
    assert!(total >= 10_000, "only {total} cases");
    // The resealed kinds must reach past the checksums: some of them decode.
    for kind in [Kind::TableField, Kind::Content, Kind::Sections] {
        let accepted = tallies.iter().find(|(k, _)| *k == kind).map_or(0, |(_, t)| t.accepted);
        assert!(accepted > 0, "no {kind} case decoded: the mutations never get past the checksums");
    }
}
