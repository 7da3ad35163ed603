//! The latest live message of every channel, for viewers who subscribe
//! later. The Foxglove SDK keeps none: a viewer who joins a run after its
//! last map went out, or while the views linger after the run, would see
//! no map, no robot and no scan until the next message, which after the
//! run never comes. ROS 2 gives `/map` transient-local durability for
//! this; the live view gives it to every channel that `sink.foxglove`
//! publishes. A channel's latched message is what live viewers were last
//! sent (or, with none watching, would have been), and a viewer gets it
//! once as it subscribes, from the server's listener ([`Replay`]).
//!
//! Latching costs one encoding per live message, into a buffer kept per
//! channel, and only once a live server runs ([`enable`]): a run that only
//! records pays nothing. `/squall/metrics` is not latched: it carries one
//! message per component, and the next comes within a second.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{ChannelId, Encode, PartialMetadata, RawChannel};

/// A channel's latest live message.
struct Latched {
    channel: Arc<RawChannel>,
    message: Vec<u8>,
    log_time: u64,
}

/// Every live channel's latest message, by channel.
fn latest() -> &'static Mutex<HashMap<ChannelId, Latched>> {
    static LATEST: OnceLock<Mutex<HashMap<ChannelId, Latched>>> = OnceLock::new();
    LATEST.get_or_init(Default::default)
}

static ENABLED: AtomicBool = AtomicBool::new(false);

/// Latches from now on: called when a live server starts.
pub(super) fn enable() {
    ENABLED.store(true, Ordering::Relaxed);
}

/// True once a live server has started: live messages are then due even
/// with nobody watching, to be latched.
pub(super) fn enabled() -> bool {
    ENABLED.load(Ordering::Relaxed)
}

/// Sends `msg` to `channel`'s live viewers at `log_time` (nanoseconds
/// since the epoch) and keeps it as the channel's latest. The lock is held
/// while sending, so that a viewer subscribing meanwhile gets this message
/// or the one before, never the one before after this one. A message that
/// cannot be encoded is neither sent nor kept.
pub(super) fn send<T: Encode>(channel: &Arc<RawChannel>, msg: &T, log_time: u64) {
    let mut latest = latest().lock().unwrap_or_else(|e| e.into_inner());
    let latched = latest.entry(channel.id()).or_insert_with(|| Latched {
        channel: channel.clone(),
        message: Vec::new(),
        log_time,
    });
    latched.message.clear();
    if msg.encode(&mut latched.message).is_err() {
        latest.remove(&channel.id());
        return;
    }
    latched.log_time = log_time;
    if channel.has_sinks() {
        channel.log_with_meta(&latched.message, PartialMetadata::with_log_time(log_time));
    }
}

/// Sends the latest message of `channel`, if it has one, to the viewer
/// `client` alone.
fn replay(channel: ChannelId, client: &Client) {
    let Some(sink) = client.sink_id() else { return };
    let latest = latest().lock().unwrap_or_else(|e| e.into_inner());
    if let Some(l) = latest.get(&channel) {
        l.channel.log_with_meta_to_sink(&l.message, PartialMetadata::with_log_time(l.log_time), Some(sink));
    }
}

/// The live server's listener: a viewer subscribing to a channel gets its
/// latest message.
#[derive(Debug)]
pub(super) struct Replay;

impl ServerListener for Replay {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        replay(channel.id(), &client);
    }
}
