//! A ROS 2 bag's MCAP file, read whole as `squall slam --bag` reads one:
//! the container, the messages on the default topics, and the scans'
//! poses interpolated from odometry.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use squall::spouts::rosbag2::{Topics, read_mcap_bytes};

fuzz_target!(|bytes: &[u8]| {
    let strict = Topics::default();
    let _ = read_mcap_bytes(Path::new("fuzz.mcap"), bytes, &strict);
    let lenient = Topics { skip_bad: true, ..Topics::default() };
    let _ = read_mcap_bytes(Path::new("fuzz.mcap"), bytes, &lenient);
});
