//! The envelope: preamble, header, body; strict decode with errors that say what was wrong.

use serde::{Deserialize, Serialize};

use super::{Header, Message, MessageKind, PREAMBLE_LEN, WIRE_VERSION};

/// A decoded message with its header.
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped<M> {
    pub header: Header,
    pub msg: M,
}

/// Why a payload could not be decoded. Every variant names the expected message type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("{expected}: empty payload")]
    Empty { expected: &'static str },
    #[error("{expected}: unknown wire version {found} (this build reads version {WIRE_VERSION})")]
    UnknownVersion { expected: &'static str, found: u8 },
    #[error("{expected}: unknown message kind {found}")]
    UnknownKind { expected: &'static str, found: u8 },
    #[error("{expected}: payload holds a {found} message (is a key remapped to the wrong topic?)")]
    WrongKind { expected: &'static str, found: &'static str },
    #[error("{expected}: truncated in the {part} ({len} bytes in all)")]
    Truncated { expected: &'static str, part: &'static str, len: usize },
    #[error("{expected}: malformed {part}: {reason}")]
    Malformed { expected: &'static str, part: &'static str, reason: String },
    #[error("{expected}: {count} trailing bytes after a complete message")]
    TrailingBytes { expected: &'static str, count: usize },
    #[error("{expected}: invalid content: {reason}")]
    Invalid { expected: &'static str, reason: String },
}

/// Encodes a message with its header into a new buffer.
pub fn encode<M: Message>(header: &Header, msg: &M) -> Vec<u8> {
    let mut buf = Vec::new();
    encode_into(&mut buf, header, msg);
    buf
}

/// Encodes a message with its header, appending to `buf` (reuse a buffer on hot paths).
pub fn encode_into<M: Message>(buf: &mut Vec<u8>, header: &Header, msg: &M) {
    buf.push(WIRE_VERSION);
    buf.push(M::KIND as u8);
    write_postcard(buf, header);
    write_postcard(buf, msg);
}

/// Appends postcard bytes of `value` to `buf`.
pub(crate) fn write_postcard<T: Serialize + ?Sized>(buf: &mut Vec<u8>, value: &T) {
    // Serializing our own types into a growable Vec cannot fail: no custom serializer here
    // returns an error and the flavor has no capacity limit.
    if let Err(e) = postcard::to_io(value, &mut *buf) {
        unreachable!("postcard into a Vec failed: {e}");
    }
}

/// Reads preamble and header only: what statistics need, without decoding the body.
/// Returns the kind, the header and the offset of the body.
pub fn decode_header(bytes: &[u8], expected: MessageKind) -> Result<(Header, usize), DecodeError> {
    let exp = expected.name();
    let Some(&version) = bytes.first() else {
        return Err(DecodeError::Empty { expected: exp });
    };
    if version != WIRE_VERSION {
        return Err(DecodeError::UnknownVersion { expected: exp, found: version });
    }
    let Some(&kind_byte) = bytes.get(1) else {
        return Err(DecodeError::Truncated { expected: exp, part: "preamble", len: bytes.len() });
    };
    let kind = MessageKind::from_u8(kind_byte).ok_or(DecodeError::UnknownKind { expected: exp, found: kind_byte })?;
    if kind != expected {
        return Err(DecodeError::WrongKind { expected: exp, found: kind.name() });
    }
    let after_preamble = &bytes[PREAMBLE_LEN..];
    let (header, rest) = postcard::take_from_bytes::<Header>(after_preamble)
        .map_err(|e| postcard_error(e, exp, "header", bytes.len()))?;
    Ok((header, bytes.len() - rest.len()))
}

/// Decodes one whole payload strictly. `M` may borrow from `bytes` (see `CameraFrameRef`).
pub fn decode<'a, M>(bytes: &'a [u8]) -> Result<Stamped<M>, DecodeError>
where
    M: Message + Deserialize<'a>,
{
    let (header, body_at) = decode_header(bytes, M::KIND)?;
    let exp = M::KIND.name();
    let (msg, rest) =
        postcard::take_from_bytes::<M>(&bytes[body_at..]).map_err(|e| postcard_error(e, exp, "body", bytes.len()))?;
    if !rest.is_empty() {
        return Err(DecodeError::TrailingBytes { expected: exp, count: rest.len() });
    }
    msg.check().map_err(|e| DecodeError::Invalid { expected: exp, reason: e.0 })?;
    Ok(Stamped { header, msg })
}

fn postcard_error(e: postcard::Error, expected: &'static str, part: &'static str, len: usize) -> DecodeError {
    use postcard::Error as P;
    let reason = match e {
        P::DeserializeUnexpectedEnd => return DecodeError::Truncated { expected, part, len },
        P::DeserializeBadVarint => "a varint is longer than its type allows".to_string(),
        P::DeserializeBadBool => "a bool byte is neither 0 nor 1".to_string(),
        P::DeserializeBadOption => "an option tag is neither 0 nor 1".to_string(),
        // serde's derived enums report an unknown tag through a custom error, whose text
        // postcard does not keep.
        P::DeserializeBadEnum | P::SerdeDeCustom => {
            "an enum tag names no variant, or a value is invalid for its type".to_string()
        }
        P::DeserializeBadUtf8 | P::DeserializeBadChar => "a string is not valid UTF-8".to_string(),
        other => other.to_string(),
    };
    DecodeError::Malformed { expected, part, reason }
}
