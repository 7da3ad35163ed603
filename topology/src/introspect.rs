//! Discovers the field names of a serde struct without a value of it.
//!
//! `#[derive(Deserialize)]` passes the struct's field list to
//! `Deserializer::deserialize_struct`; a deserializer that captures that list
//! and stops is enough to learn which fields a `fields` grouping may name.

use std::fmt;

use serde::de::{self, DeserializeOwned, Visitor};

/// The field names of `T` if it deserializes as a struct, else `None`.
pub(crate) fn struct_field_names<T: DeserializeOwned>() -> Option<&'static [&'static str]> {
    match T::deserialize(Introspector) {
        Err(Stop(fields)) => fields,
        Ok(_) => None,
    }
}

struct Introspector;

#[derive(Debug)]
struct Stop(Option<&'static [&'static str]>);

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("introspection stop")
    }
}

impl std::error::Error for Stop {}

impl de::Error for Stop {
    fn custom<T: fmt::Display>(_msg: T) -> Self {
        Stop(None)
    }
}

impl<'de> de::Deserializer<'de> for Introspector {
    type Error = Stop;

    fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, Stop> {
        Err(Stop(None))
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        _visitor: V,
    ) -> Result<V::Value, Stop> {
        Err(Stop(Some(fields)))
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf option unit unit_struct newtype_struct seq tuple
        tuple_struct map enum identifier ignored_any
    }
}
