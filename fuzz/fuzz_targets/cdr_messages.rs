//! CDR-encoded ROS 2 messages, as they come out of a bag or off the live
//! link: the first byte picks the message type, the rest is the message.
#![no_main]

use libfuzzer_sys::fuzz_target;
use squall::spouts::rosbag2::messages;

fuzz_target!(|data: &[u8]| {
    let Some((&kind, bytes)) = data.split_first() else { return };
    match kind % 4 {
        0 => drop(messages::laser_scan(bytes)),
        1 => drop(messages::odometry(bytes)),
        2 => drop(messages::tf_message(bytes)),
        _ => drop(messages::read_pose_stamped(bytes)),
    }
});
