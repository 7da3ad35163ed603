//! What crosses processes in a cluster run, as a worker or coordinator
//! receives it: the first byte picks a frame or a task's latency histogram
//! (HdrHistogram's V2 encoding), the rest is the bytes off the network.
#![no_main]

use libfuzzer_sys::fuzz_target;
use squall::topology::cluster::outcome::decode_histogram;
use squall::topology::cluster::wire::{DEFAULT_MAX_FRAME, Frame};

fuzz_target!(|data: &[u8]| {
    let Some((&kind, bytes)) = data.split_first() else { return };
    if kind % 2 == 0 {
        if let Ok(frame) = Frame::decode(bytes, DEFAULT_MAX_FRAME) {
            // What a peer accepts, it can send on.
            assert!(Frame::decode(&frame.encode(), usize::MAX).is_ok(), "{frame:?}");
        }
    } else {
        let _ = decode_histogram(bytes);
    }
});
