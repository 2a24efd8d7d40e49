//! Decoding a payload whose type is known only from its kind byte: what `slipstream echo` and
//! `slipstream top` do with every key they see.

use serde_json::{json, Value};

use super::{
    decode, AccCommand, AccStatus, CameraFrameRef, CameraInfo, ControlCommand, DecodeError, Detections,
    GroundTruthObjects, Header, MessageKind, RoadSpec, SimClock, SimEvent, Speed, VehicleState, PREAMBLE_LEN,
    WIRE_VERSION,
};

/// The kind a payload says it holds (version and kind bytes only).
pub fn peek_kind(bytes: &[u8]) -> Result<MessageKind, DecodeError> {
    let exp = "message";
    let Some(&version) = bytes.first() else {
        return Err(DecodeError::Empty { expected: exp });
    };
    if version != WIRE_VERSION {
        return Err(DecodeError::UnknownVersion { expected: exp, found: version });
    }
    let Some(&kind) = bytes.get(PREAMBLE_LEN - 1) else {
        return Err(DecodeError::Truncated { expected: exp, part: "preamble", len: bytes.len() });
    };
    MessageKind::from_u8(kind).ok_or(DecodeError::UnknownKind { expected: exp, found: kind })
}

/// A whole payload, decoded strictly by its kind, as JSON. A camera frame is summarized (size,
/// encoding, byte count), its pixels viewed in place and not copied.
pub fn decode_json(bytes: &[u8]) -> Result<(MessageKind, Header, Value), DecodeError> {
    let kind = peek_kind(bytes)?;
    fn as_json<'a, M>(bytes: &'a [u8]) -> Result<(Header, Value), DecodeError>
    where
        M: super::Message + serde::Deserialize<'a>,
    {
        let s = decode::<M>(bytes)?;
        // Every message is plain data: to_value cannot fail on it.
        Ok((s.header, serde_json::to_value(&s.msg).unwrap_or(Value::Null)))
    }
    let (header, body) = match kind {
        MessageKind::Speed => as_json::<Speed>(bytes)?,
        MessageKind::VehicleState => as_json::<VehicleState>(bytes)?,
        MessageKind::ControlCommand => as_json::<ControlCommand>(bytes)?,
        MessageKind::CameraFrame => {
            let s = decode::<CameraFrameRef>(bytes)?;
            let f = &s.msg;
            (
                s.header,
                json!({ "width": f.width, "height": f.height, "encoding": f.encoding, "data_bytes": f.data.len() }),
            )
        }
        MessageKind::CameraInfo => as_json::<CameraInfo>(bytes)?,
        MessageKind::GroundTruthObjects => as_json::<GroundTruthObjects>(bytes)?,
        MessageKind::Detections => as_json::<Detections>(bytes)?,
        MessageKind::SimClock => as_json::<SimClock>(bytes)?,
        MessageKind::SimEvent => as_json::<SimEvent>(bytes)?,
        MessageKind::AccStatus => as_json::<AccStatus>(bytes)?,
        MessageKind::AccCommand => as_json::<AccCommand>(bytes)?,
        MessageKind::RoadMap => as_json::<RoadSpec>(bytes)?,
        MessageKind::EgoInfo => as_json::<super::EgoInfo>(bytes)?,
    };
    Ok((kind, header, body))
}
