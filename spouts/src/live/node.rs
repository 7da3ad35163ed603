//! squall as a ROS 2 node on a zenoh session, as rmw_zenoh shapes one:
//! a liveliness token for the node, one for each publisher and
//! subscription, keys with type hashes, and the attachment on every
//! sample (see [`crate::rmw_zenoh`]). Transient-local publishers (the
//! map) keep their last samples in zenoh-ext's advanced publisher cache,
//! where rmw_zenoh's late subscribers ask for them.

use std::sync::{Arc, Weak};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use squall_topology::BoxError;
use zenoh::Session;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh_ext::{AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};

use crate::rmw_zenoh::{
    Attachment, Durability, Entity, MessageType, NodeName, Qos, topic_key, topic_key_any_hash,
};

/// One ROS 2 node on a session: components of one process that name the
/// same session, domain and node share it, as the nodes of one ROS 2
/// process share a context.
#[derive(Debug)]
pub struct RosNode {
    session: Session,
    name: NodeName,
    /// The next entity id (the node has 0).
    next_entity: std::sync::atomic::AtomicU64,
    _token: LivelinessToken,
}

/// A declared node: session id, domain, name.
type NodeEntry = (String, u32, String, Weak<RosNode>);

/// The nodes declared; held while one is declared, so that two
/// components opening at once get one node.
static NODES: tokio::sync::Mutex<Vec<NodeEntry>> = tokio::sync::Mutex::const_new(Vec::new());

impl RosNode {
    /// The node `name` in `domain` on `session`, declared (its liveliness
    /// token) on first use.
    pub async fn shared(session: &Session, domain: u32, name: &str) -> Result<Arc<RosNode>, BoxError> {
        let zid = session.zid().to_string();
        let mut nodes = NODES.lock().await;
        nodes.retain(|(_, _, _, n)| n.strong_count() > 0);
        let found = nodes.iter().find(|(z, d, n, _)| *z == zid && *d == domain && n == name);
        if let Some(node) = found.and_then(|e| e.3.upgrade()) {
            return Ok(node);
        }
        let name =
            NodeName { domain, zid: zid.clone(), id: 0, namespace: "/".into(), name: name.to_string() };
        let token = session.liveliness().declare_token(name.token()).await?;
        let node = Arc::new(RosNode {
            session: session.clone(),
            name,
            next_entity: std::sync::atomic::AtomicU64::new(1),
            _token: token,
        });
        nodes.push((zid, domain, node.name.name.clone(), Arc::downgrade(&node)));
        Ok(node)
    }

    fn token(&self, kind: Entity, topic: &str, ty: &MessageType, qos: &Qos) -> String {
        let id = self.next_entity.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.name.entity_token(id, kind, topic, ty, qos)
    }

    /// A publisher of `ty` on `topic` (fully qualified) with `qos`.
    pub async fn publisher(&self, topic: &str, ty: &MessageType, qos: Qos) -> Result<RosPublisher, BoxError> {
        let token_key = self.token(Entity::Publisher, topic, ty, &qos);
        let gid = crate::rmw_zenoh::gid(&token_key);
        let key = topic_key(self.name.domain, topic, ty);
        // A message waits for room on a busy link rather than being lost;
        // it goes to other processes only (squall's own `/tf`
        // subscriptions, which look for the robot's odometry, neither
        // need the correction nor count as someone listening).
        let builder = self
            .session
            .declare_publisher(key)
            .congestion_control(CongestionControl::Block)
            .allowed_destination(zenoh::sample::Locality::Remote);
        let inner = match qos.durability {
            Durability::Volatile => Inner::Plain(builder.await?),
            // As rmw_zenoh declares a transient-local, reliable publisher:
            // a cache of `depth` samples, detectable by late subscribers,
            // with sequence numbers and a heartbeat for the last one.
            Durability::TransientLocal => Inner::Cached(
                builder
                    .cache(CacheConfig::default().max_samples(qos.depth))
                    .publisher_detection()
                    .sample_miss_detection(
                        MissDetectionConfig::default().sporadic_heartbeat(Duration::from_millis(500)),
                    )
                    .await?,
            ),
        };
        let token = self.session.liveliness().declare_token(token_key).await?;
        Ok(RosPublisher { inner, gid, sequence: 0, _token: token })
    }

    /// A subscription to `ty` on `topic` (any type hash), announced by its
    /// token, its samples delivered to `handler` (a FIFO that holds the
    /// link when full, or a ring that lets the oldest go).
    pub async fn subscription<H>(
        &self,
        topic: &str,
        ty: &MessageType,
        handler: H,
    ) -> Result<RosSubscription<H::Handler>, BoxError>
    where
        H: zenoh::handlers::IntoHandler<zenoh::sample::Sample> + Send,
        H::Handler: Send,
    {
        let token_key = self.token(Entity::Subscription, topic, ty, &Qos::DEFAULT);
        let subscriber = self
            .session
            .declare_subscriber(topic_key_any_hash(self.name.domain, topic, ty))
            .with(handler)
            .await?;
        let token = self.session.liveliness().declare_token(token_key).await?;
        Ok(RosSubscription { subscriber, _token: token })
    }
}

enum Inner {
    Plain(zenoh::pubsub::Publisher<'static>),
    Cached(zenoh_ext::AdvancedPublisher<'static>),
}

impl std::fmt::Debug for Inner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Inner::Plain(_) => "Plain",
            Inner::Cached(_) => "Cached",
        })
    }
}

/// A publisher that stamps every sample with rmw_zenoh's attachment.
#[derive(Debug)]
pub struct RosPublisher {
    inner: Inner,
    gid: [u8; 16],
    /// Samples sent so far.
    sequence: i64,
    _token: LivelinessToken,
}

impl RosPublisher {
    /// Whether any subscriber listens (zenoh drops what nobody hears).
    pub async fn matching(&self) -> Result<bool, BoxError> {
        Ok(match &self.inner {
            Inner::Plain(p) => p.matching_status().await?.matching(),
            Inner::Cached(p) => p.matching_status().await?.matching(),
        })
    }

    /// Whether it keeps its last samples for late subscribers.
    pub fn transient_local(&self) -> bool {
        matches!(self.inner, Inner::Cached(_))
    }

    /// Sends `bytes` (a CDR message) with the next attachment.
    pub async fn put(&mut self, bytes: Vec<u8>) -> Result<(), BoxError> {
        self.sequence += 1;
        let stamp_ns = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as i64);
        let attachment = Attachment { sequence: self.sequence, stamp_ns, gid: self.gid }.encode().to_vec();
        match &self.inner {
            Inner::Plain(p) => p.put(bytes).attachment(attachment).await?,
            Inner::Cached(p) => p.put(bytes).attachment(attachment).await?,
        }
        Ok(())
    }
}

/// A subscription and its token.
#[derive(Debug)]
pub struct RosSubscription<H> {
    /// The samples received.
    pub subscriber: zenoh::pubsub::Subscriber<H>,
    _token: LivelinessToken,
}
