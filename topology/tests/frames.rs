//! Frames from the network are checked before they cost anything: a
//! frame whose header claims a gigabyte is refused without that gigabyte
//! (or any large part of it) ever being allocated. This binary counts
//! the allocations of its own process to show it.
#![cfg(feature = "cluster")]

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use squall_topology::cluster::wire::{DEFAULT_MAX_FRAME, Frame, WireError};

/// The system allocator, remembering the largest single request.
struct Largest;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call goes to the system allocator unchanged; the only
// addition is an atomic maximum.
unsafe impl GlobalAlloc for Largest {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract, passed on.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        // SAFETY: the caller's contract, passed on.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Largest = Largest;

/// LEB128, as postcard writes lengths.
fn varint(mut n: u64) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let byte = (n & 0x7f) as u8;
        n >>= 7;
        if n == 0 {
            out.push(byte);
            return out;
        }
        out.push(byte | 0x80);
    }
}

/// The bytes of `frame`, whose last field, a length, claims `claimed`
/// items, followed by only `actual` bytes.
fn lying_frame(frame: &Frame, claimed: u64, actual: usize) -> Vec<u8> {
    let mut bytes = frame.encode();
    assert_eq!(bytes.pop(), Some(0), "the frame ends with an empty list's length");
    bytes.extend(varint(claimed));
    bytes.extend(std::iter::repeat_n(7u8, actual));
    bytes
}

#[test]
fn a_frame_claiming_a_gigabyte_is_refused_without_allocating_it() {
    // The instrument sees a large allocation.
    LARGEST.store(0, Ordering::Relaxed);
    drop(std::hint::black_box(vec![1u8; 2 << 20]));
    assert!(LARGEST.load(Ordering::Relaxed) >= 2 << 20);
    let one_gb = 1u64 << 30;
    let frames = [
        // A tuple whose payload claims 1 GiB.
        lying_frame(&Frame::Tuple { sender: 1, edge: 0, from: 0, to: 0, payload: Vec::new() }, one_gb, 64),
        // A batch claiming 2^30 payloads.
        lying_frame(&Frame::Tuples { sender: 1, edge: 0, from: 0, to: 0, payloads: Vec::new() }, one_gb, 64),
    ];
    for bytes in frames {
        LARGEST.store(0, Ordering::Relaxed);
        let refused = Frame::decode(&bytes, DEFAULT_MAX_FRAME);
        let largest = LARGEST.load(Ordering::Relaxed);
        assert!(matches!(refused, Err(WireError::Malformed(_))), "{refused:?}");
        assert!(largest <= 1 << 20, "decoding allocated {largest} bytes at once");
    }
    // A frame over the limit is refused before its body is looked at.
    let big = vec![0u8; DEFAULT_MAX_FRAME + 1];
    LARGEST.store(0, Ordering::Relaxed);
    assert!(matches!(Frame::decode(&big, DEFAULT_MAX_FRAME), Err(WireError::TooLarge { .. })));
    let largest = LARGEST.load(Ordering::Relaxed);
    assert!(largest <= 1 << 20, "refusing it allocated {largest} bytes at once");
}
