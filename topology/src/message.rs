//! Stream message types.
//!
//! A stream carries exactly one Rust type. Inside one process a message travels
//! as an `Arc<dyn Any>` ([`Payload`]); a [`MessageType`] is the run-time
//! description of the type that lets the engine check stream/input
//! compatibility at build time, hash key fields for `fields` grouping, and
//! serialize the message when it leaves the process.

use std::any::{Any, TypeId};
use std::fmt;
use std::sync::Arc;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::error::CodecError;
use crate::field_hash::{FieldHashError, hash_fields};
use crate::introspect::struct_field_names;

/// A value that can travel on a stream: serde-serializable (for crossing
/// processes), shareable between threads, and owned.
pub trait Message: Serialize + DeserializeOwned + Send + Sync + 'static {}

impl<T: Serialize + DeserializeOwned + Send + Sync + 'static> Message for T {}

/// A message as it travels inside one process: shared, never copied.
pub type Payload = Arc<dyn Any + Send + Sync>;

/// A message that, sent again and again from one task to another in
/// another process, need not carry what the receiver already holds (a
/// particle's map tiles). Sender and receiver each keep a record for the
/// pair; messages between them arrive in order, so the records stay in
/// step. Within one process the message travels as an `Arc`, as any other.
pub trait Incremental: Message {
    /// What a sending task remembers of one receiving task.
    type Sent: Default + Send + 'static;
    /// What a receiving task keeps of one sending task.
    type Held: Default + Send + 'static;

    /// The message's bytes, leaving out what `sent` says the receiver
    /// holds (and recording what it will hold).
    fn encode_incremental(&self, sent: &mut Self::Sent) -> Result<Vec<u8>, CodecError>;

    /// The message back from its bytes and what the receiver holds; an
    /// error if the bytes are damaged or refer to something not held.
    fn decode_incremental(bytes: &[u8], held: &mut Self::Held) -> Result<Self, CodecError>;
}

/// Per-pair state of an [`Incremental`] codec, type-erased.
pub(crate) type CodecState = Box<dyn Any + Send>;

/// The type-erased [`Incremental`] codec of a message type (used by
/// cluster runs).
#[derive(Clone, Copy)]
#[cfg_attr(not(feature = "cluster"), allow(dead_code))]
pub(crate) struct IncrementalCodec {
    pub(crate) new_sent: fn() -> CodecState,
    pub(crate) new_held: fn() -> CodecState,
    pub(crate) encode: fn(&(dyn Any + Send + Sync), &mut CodecState) -> Result<Vec<u8>, CodecError>,
    pub(crate) decode: fn(&[u8], &mut CodecState) -> Result<Payload, CodecError>,
}

/// Run-time description of a stream's message type.
///
/// Two `MessageType`s are equal when they describe the same Rust type.
#[derive(Clone, Copy)]
pub struct MessageType {
    id: TypeId,
    name: &'static str,
    fields: Option<&'static [&'static str]>,
    hash: fn(&(dyn Any + Send + Sync), &[&str]) -> Result<u64, FieldHashError>,
    encode: fn(&(dyn Any + Send + Sync)) -> Result<Vec<u8>, postcard::Error>,
    decode: fn(&[u8]) -> Result<Payload, postcard::Error>,
    #[cfg_attr(not(feature = "cluster"), allow(dead_code))]
    incremental: Option<IncrementalCodec>,
}

impl MessageType {
    /// The description of `T`.
    pub fn of<T: Message>() -> Self {
        MessageType {
            id: TypeId::of::<T>(),
            name: std::any::type_name::<T>(),
            fields: struct_field_names::<T>(),
            hash: hash_payload::<T>,
            encode: encode_payload::<T>,
            decode: decode_payload::<T>,
            incremental: None,
        }
    }

    /// The description of `T`, which crosses processes incrementally.
    pub fn incremental<T: Incremental>() -> Self {
        MessageType {
            incremental: Some(IncrementalCodec {
                new_sent: || Box::new(T::Sent::default()),
                new_held: || Box::new(T::Held::default()),
                encode: encode_incremental::<T>,
                decode: decode_incremental::<T>,
            }),
            ..Self::of::<T>()
        }
    }

    /// The incremental codec, if the type has one.
    #[cfg_attr(not(feature = "cluster"), allow(dead_code))]
    pub(crate) fn incremental_codec(&self) -> Option<IncrementalCodec> {
        self.incremental
    }

    /// The Rust type name, for error messages.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// Whether this describes `T`.
    pub fn is<T: 'static>(&self) -> bool {
        self.id == TypeId::of::<T>()
    }

    /// The named fields of the type when it is a struct; `None` otherwise.
    /// These are the names a `fields` grouping may use.
    pub fn fields(&self) -> Option<&'static [&'static str]> {
        self.fields
    }

    /// Whether `field` is a named field of this type.
    pub fn has_field(&self, field: &str) -> bool {
        self.fields.is_some_and(|f| f.contains(&field))
    }

    /// A stable (across processes and runs) hash of the named fields of
    /// `payload`, which must be of this type.
    pub fn hash_fields(
        &self,
        payload: &(dyn Any + Send + Sync),
        fields: &[&str],
    ) -> Result<u64, FieldHashError> {
        (self.hash)(payload, fields)
    }

    /// Serializes `payload` (which must be of this type) with postcard.
    pub fn encode(&self, payload: &(dyn Any + Send + Sync)) -> Result<Vec<u8>, postcard::Error> {
        (self.encode)(payload)
    }

    /// Deserializes a payload of this type from postcard bytes.
    pub fn decode(&self, bytes: &[u8]) -> Result<Payload, postcard::Error> {
        (self.decode)(bytes)
    }

    /// Whether `payload` holds a value of this type.
    pub fn matches(&self, payload: &(dyn Any + Send + Sync)) -> bool {
        payload.type_id() == self.id
    }
}

impl PartialEq for MessageType {
    fn eq(&self, other: &Self) -> bool {
        self.id == other.id
    }
}

impl Eq for MessageType {}

impl fmt::Debug for MessageType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

fn downcast<T: 'static>(payload: &(dyn Any + Send + Sync)) -> &T {
    payload.downcast_ref::<T>().expect("MessageType used with a payload of another type")
}

fn hash_payload<T: Message>(
    payload: &(dyn Any + Send + Sync),
    fields: &[&str],
) -> Result<u64, FieldHashError> {
    hash_fields(downcast::<T>(payload), fields)
}

fn encode_payload<T: Message>(payload: &(dyn Any + Send + Sync)) -> Result<Vec<u8>, postcard::Error> {
    postcard::to_stdvec(downcast::<T>(payload))
}

fn decode_payload<T: Message>(bytes: &[u8]) -> Result<Payload, postcard::Error> {
    Ok(Arc::new(postcard::from_bytes::<T>(bytes)?))
}

fn encode_incremental<T: Incremental>(
    payload: &(dyn Any + Send + Sync),
    sent: &mut CodecState,
) -> Result<Vec<u8>, CodecError> {
    let sent = sent.downcast_mut::<T::Sent>().expect("the codec's own sender state");
    downcast::<T>(payload).encode_incremental(sent)
}

fn decode_incremental<T: Incremental>(bytes: &[u8], held: &mut CodecState) -> Result<Payload, CodecError> {
    let held = held.downcast_mut::<T::Held>().expect("the codec's own receiver state");
    Ok(Arc::new(T::decode_incremental(bytes, held)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Reading {
        robot: String,
        seq: u64,
    }

    #[test]
    fn describes_struct_fields() {
        let t = MessageType::of::<Reading>();
        assert_eq!(t.fields(), Some(&["robot", "seq"][..]));
        assert!(t.has_field("robot"));
        assert!(!t.has_field("pose"));
        assert!(MessageType::of::<String>().fields().is_none());
    }

    #[test]
    fn equality_is_by_type() {
        assert_eq!(MessageType::of::<Reading>(), MessageType::of::<Reading>());
        assert_ne!(MessageType::of::<Reading>(), MessageType::of::<String>());
    }

    #[test]
    fn encode_decode_round_trip() {
        let t = MessageType::of::<Reading>();
        let value = Reading { robot: "r1".into(), seq: 7 };
        let bytes = t.encode(&value).unwrap();
        let back = t.decode(&bytes).unwrap();
        assert_eq!(back.downcast_ref::<Reading>(), Some(&value));
    }
}
