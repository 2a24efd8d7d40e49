//! The ROS 2 face's errors, one type for the whole face: its catalog of message types, CDR in
//! and out, rmw_zenoh's attachments and names, and the bus payloads it translates. A caller
//! (the live face, `record --profile ros2`, `convert`) can tell a type the face does not know
//! from a payload that does not decode, and counts the ones per message apart from the ones
//! of its configuration.

use slipstream_contract::msg::{DecodeError, ImageEncoding};

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Ros2Error {
    /// A type name the catalog does not hold.
    #[error("`{name}` is not a type the bridge knows (known: {known})")]
    UnknownType { name: String, known: String },
    /// A name that is not `package/msg/Type`.
    #[error("`{0}` is not `package/msg/Type`")]
    BadTypeName(String),
    /// A definition of the catalog that does not parse (a defect of the catalog itself).
    #[error("{type_name}: {problem}")]
    Definition { type_name: String, problem: String },
    /// A namespace that is not a ROS namespace.
    #[error("`{0}` is not a ROS namespace")]
    Namespace(String),
    /// CDR that hiroz-cdr could not write.
    #[error("CDR encoding failed: {0}")]
    Encode(String),
    /// A CDR payload that does not decode as its type.
    #[error("{0}")]
    Cdr(String),
    /// A sample whose attachment is not rmw_zenoh's (sequence number, timestamp, gid).
    #[error("the attachment is not rmw_zenoh's: {0}")]
    Attachment(String),
    /// A bus payload that does not decode as its topic's message.
    #[error(transparent)]
    Payload(#[from] DecodeError),
    /// A camera frame whose encoding the route's configured type cannot carry.
    #[error(
        "{topic} frames are {encoding:?} but ros2.topics.{route}.type is {configured} (fix: set it to {fix}, or leave it out)"
    )]
    FrameType {
        topic: String,
        encoding: ImageEncoding,
        route: &'static str,
        configured: &'static str,
        fix: &'static str,
    },
}
