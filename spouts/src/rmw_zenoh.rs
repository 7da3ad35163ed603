//! rmw_zenoh's conventions, so ROS 2 nodes running over rmw_zenoh
//! (`RMW_IMPLEMENTATION=rmw_zenoh_cpp`) see squall's live link as one of
//! their own: the key expression of each topic, the attachment every
//! sample carries, the liveliness tokens that make nodes, publishers and
//! subscriptions appear in `ros2 node list` / `ros2 topic list`, and the
//! QoS each token states. Pure formatting and parsing; the live link
//! ([`crate::live`]) declares them on a zenoh session.
//!
//! Written from rmw_zenoh's design document (`docs/design.md`) and its
//! sources (`liveliness_utils.cpp`, `attachment_helpers.cpp`, `qos.cpp`;
//! Jazzy ≥ 0.2.4, Kilted, Rolling, 2025). Decision 0028 says what was
//! checked against an independent client and what was not.

/// A ROS 2 message type: its name and its RIHS01 type hash (REP 2011),
/// which rmw_zenoh puts in every key so only publishers and subscribers
/// of the same definition meet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageType {
    /// `package/msg/Name`.
    pub name: &'static str,
    /// `RIHS01_` and 64 hex digits.
    pub hash: &'static str,
}

impl MessageType {
    /// The DDS type name rmw_zenoh uses: `package::msg::dds_::Name_`.
    pub fn dds_name(&self) -> String {
        let mut parts = self.name.split('/');
        let (package, kind, name) = (parts.next(), parts.next(), parts.next());
        format!("{}::{}::dds_::{}_", package.unwrap_or(""), kind.unwrap_or("msg"), name.unwrap_or(""))
    }
}

/// The types' hashes are those of Humble's, Jazzy's and Kilted's
/// definitions (the same for these messages), as `ros2 bag record` writes
/// them in `metadata.yaml`; `tests/live_link.rs` recomputes them with the
/// `rosbags` package.
pub const LASER_SCAN: MessageType = MessageType {
    name: "sensor_msgs/msg/LaserScan",
    hash: "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
};
/// `nav_msgs/msg/Odometry`.
pub const ODOMETRY: MessageType = MessageType {
    name: "nav_msgs/msg/Odometry",
    hash: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
};
/// `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE: MessageType = MessageType {
    name: "tf2_msgs/msg/TFMessage",
    hash: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
};
/// `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED: MessageType = MessageType {
    name: "geometry_msgs/msg/PoseStamped",
    hash: "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
};
/// `nav_msgs/msg/OccupancyGrid`.
pub const OCCUPANCY_GRID: MessageType = MessageType {
    name: "nav_msgs/msg/OccupancyGrid",
    hash: "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7",
};

/// Why a ROS name cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0:?} is not a ROS 2 name: expected `/`-separated tokens of letters, digits and `_`")]
pub struct NameError(pub String);

/// Checks a topic or node name as ROS 2 does (letters, digits, `_` and
/// `/`, no empty tokens, not starting with a digit) and returns it fully
/// qualified (a leading `/`).
pub fn qualified(name: &str) -> Result<String, NameError> {
    let bare = name.strip_prefix('/').unwrap_or(name);
    if bare.is_empty() || !bare.split('/').all(is_token) {
        return Err(NameError(name.to_string()));
    }
    Ok(format!("/{bare}"))
}

/// Checks a node name: one token (letters, digits and `_`, not starting
/// with a digit).
pub fn node_name(name: &str) -> Result<&str, NameError> {
    if is_token(name) { Ok(name) } else { Err(NameError(name.to_string())) }
}

/// One token of a ROS 2 name.
fn is_token(t: &str) -> bool {
    !t.is_empty()
        && !t.starts_with(|c: char| c.is_ascii_digit())
        && t.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The key expression samples of `topic` (fully qualified) travel on:
/// `<domain>/<topic without the leading slash>/<DDS type>/<type hash>`.
pub fn topic_key(domain: u32, topic: &str, ty: &MessageType) -> String {
    format!("{domain}/{}/{}/{}", topic.trim_start_matches('/'), ty.dds_name(), ty.hash)
}

/// The key expression a subscription listens on: any type hash, so a
/// publisher whose distribution computes none (Humble's rmw_zenoh sends
/// `TypeHashNotSupported`) is heard too.
pub fn topic_key_any_hash(domain: u32, topic: &str, ty: &MessageType) -> String {
    format!("{domain}/{}/{}/*", topic.trim_start_matches('/'), ty.dds_name())
}

/// A token's fields: `/` becomes `%` (and an empty field `%`), so each
/// is one chunk of the key expression.
pub fn mangle(name: &str) -> String {
    if name.is_empty() { "%".into() } else { name.replace('/', "%") }
}

/// When a late subscriber still gets what was published before it came.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// Only samples published while it listens.
    Volatile,
    /// The publisher keeps the last `depth` samples for subscribers that
    /// come later (a map).
    TransientLocal,
}

/// The QoS a token states: reliable, keep-last `depth`, and `durability`
/// (deadline, lifespan and liveliness at ROS 2's defaults).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Samples kept.
    pub depth: usize,
    /// Volatile or transient-local.
    pub durability: Durability,
}

impl Qos {
    /// ROS 2's default for topics: reliable, volatile, keep last 10.
    pub const DEFAULT: Qos = Qos { depth: 10, durability: Durability::Volatile };
    /// A map's: reliable, transient-local, keep last 1 (what map_server and
    /// slam_toolbox publish `/map` with).
    pub const MAP: Qos = Qos { depth: 1, durability: Durability::TransientLocal };

    /// The token's QoS field, `R:D:H,depth:DLs,DLns:LSs,LSns:LV,LVs,LVns`,
    /// each value empty where it is rmw_zenoh's default (reliable,
    /// volatile, keep-last, depth 42, infinite durations, automatic
    /// liveliness); durability transient-local is 1.
    pub fn key(&self) -> String {
        let durability = match self.durability {
            Durability::Volatile => "",
            Durability::TransientLocal => "1",
        };
        let depth = if self.depth == 42 { String::new() } else { self.depth.to_string() };
        format!(":{durability}:,{depth}:,:,:,,")
    }
}

/// What a liveliness token announces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Entity {
    /// A publisher (`MP`).
    Publisher,
    /// A subscription (`MS`).
    Subscription,
}

/// A node as its tokens name it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeName {
    /// ROS domain id.
    pub domain: u32,
    /// The zenoh session's id, as zenoh prints it.
    pub zid: String,
    /// The node's id within the session.
    pub id: u64,
    /// Namespace, fully qualified (`/` for none).
    pub namespace: String,
    /// Node name (no slashes).
    pub name: String,
}

const ADMIN_SPACE: &str = "@ros2_lv";

impl NodeName {
    /// The node's own token:
    /// `@ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/<enclave>/<namespace>/<name>`.
    pub fn token(&self) -> String {
        let (d, z, id) = (self.domain, &self.zid, self.id);
        format!("{ADMIN_SPACE}/{d}/{z}/{id}/{id}/NN/%/{}/{}", mangle(&self.namespace), mangle(&self.name))
    }

    /// A publisher's or subscription's token: the node's fields, then the
    /// topic, type, hash and QoS.
    pub fn entity_token(
        &self,
        entity_id: u64,
        kind: Entity,
        topic: &str,
        ty: &MessageType,
        qos: &Qos,
    ) -> String {
        let kind = match kind {
            Entity::Publisher => "MP",
            Entity::Subscription => "MS",
        };
        format!(
            "{ADMIN_SPACE}/{}/{}/{}/{entity_id}/{kind}/%/{}/{}/{}/{}/{}/{}",
            self.domain,
            self.zid,
            self.id,
            mangle(&self.namespace),
            mangle(&self.name),
            mangle(topic),
            mangle(&ty.dds_name()),
            mangle(ty.hash),
            qos.key()
        )
    }
}

/// A publisher's global id, as rmw_zenoh derives it: the XXH3 128-bit hash
/// of its liveliness token, low half first.
pub fn gid(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

/// The attachment on every sample: the publisher's sequence number (from
/// 1), the source timestamp (ns since the Unix epoch) and its GID,
/// serialized as zenoh-ext does (`i64` little-endian twice, then the GID
/// as a sequence: a LEB128 length, 16, and the bytes). rmw_zenoh's
/// subscriptions drop samples without it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// Sequence number of the sample from its publisher, from 1.
    pub sequence: i64,
    /// When it was published, ns since the Unix epoch.
    pub stamp_ns: i64,
    /// The publisher's GID.
    pub gid: [u8; 16],
}

/// The attachment's length in bytes.
pub const ATTACHMENT_LEN: usize = 8 + 8 + 1 + 16;

impl Attachment {
    /// Its bytes.
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut out = [0; ATTACHMENT_LEN];
        out[..8].copy_from_slice(&self.sequence.to_le_bytes());
        out[8..16].copy_from_slice(&self.stamp_ns.to_le_bytes());
        out[16] = 16;
        out[17..].copy_from_slice(&self.gid);
        out
    }

    /// Reads one; `None` unless it is exactly this layout.
    pub fn decode(bytes: &[u8]) -> Option<Attachment> {
        if bytes.len() != ATTACHMENT_LEN || bytes[16] != 16 {
            return None;
        }
        let i64_at = |at: usize| bytes[at..at + 8].try_into().ok().map(i64::from_le_bytes);
        Some(Attachment { sequence: i64_at(0)?, stamp_ns: i64_at(8)?, gid: bytes[17..].try_into().ok()? })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn types_keys_and_names_read_as_rmw_zenoh_writes_them() {
        assert_eq!(LASER_SCAN.dds_name(), "sensor_msgs::msg::dds_::LaserScan_");
        assert_eq!(
            topic_key(0, "/scan", &LASER_SCAN),
            format!("0/scan/sensor_msgs::msg::dds_::LaserScan_/{}", LASER_SCAN.hash)
        );
        assert_eq!(
            topic_key(7, "/robot1/odom", &ODOMETRY).split('/').take(3).collect::<Vec<_>>(),
            ["7", "robot1", "odom"]
        );
        assert_eq!(topic_key_any_hash(0, "/tf", &TF_MESSAGE), "0/tf/tf2_msgs::msg::dds_::TFMessage_/*");
        assert_eq!(qualified("scan").unwrap(), "/scan");
        assert_eq!(qualified("/robot1/scan").unwrap(), "/robot1/scan");
        for bad in ["", "/", "a//b", "1scan", "sc an", "scan/"] {
            assert!(qualified(bad).is_err(), "{bad:?}");
        }
        assert_eq!(node_name("squall_2"), Ok("squall_2"));
        assert!(node_name("a/b").is_err() && node_name("").is_err());
    }

    #[test]
    fn tokens_state_the_qos_as_rmw_zenoh_does() {
        assert_eq!(Qos::DEFAULT.key(), "::,10:,:,:,,");
        assert_eq!(Qos::MAP.key(), ":1:,1:,:,:,,");
        let node =
            NodeName { domain: 0, zid: "ab12".into(), id: 0, namespace: "/".into(), name: "squall".into() };
        assert_eq!(node.token(), "@ros2_lv/0/ab12/0/0/NN/%/%/squall");
        assert_eq!(
            node.entity_token(3, Entity::Publisher, "/map", &OCCUPANCY_GRID, &Qos::MAP),
            format!(
                "@ros2_lv/0/ab12/0/3/MP/%/%/squall/%map/nav_msgs::msg::dds_::OccupancyGrid_/{}/:1:,1:,:,:,,",
                OCCUPANCY_GRID.hash
            )
        );
    }

    #[test]
    fn the_attachment_and_gid_match_rmw_zenohs_bytes() {
        // The example of the design document's layout: seq 1, stamp
        // 0x0102030405060708, GID 0..15.
        let gid: [u8; 16] = std::array::from_fn(|i| i as u8);
        let a = Attachment { sequence: 1, stamp_ns: 0x0102_0304_0506_0708, gid };
        let bytes = a.encode();
        assert_eq!(bytes[..16], [1, 0, 0, 0, 0, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1]);
        assert_eq!(bytes[16], 16);
        assert_eq!(bytes[17..], gid);
        assert_eq!(Attachment::decode(&bytes), Some(a));
        assert_eq!(Attachment::decode(&bytes[..32]), None);
        // rmw_zenoh's talker in its design document: this GID is
        // xxhash's XXH3-128 of the token (checked with Python's xxhash).
        let talker = "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,";
        let hex: String = gid_hex(&super::gid(talker));
        assert_eq!(hex, "ac170f31eadcd9ff0cd86d7a17907d1c");
    }

    fn gid_hex(g: &[u8; 16]) -> String {
        g.iter().map(|b| format!("{b:02x}")).collect()
    }
}
