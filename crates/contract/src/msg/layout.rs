//! Every message type's layout as data: the serde definition of its header and body, traced by
//! `serde-reflection` into its registry format (each struct's fields in order with their
//! types, each enum's variants by index), for the schema records of recordings. Together with
//! the envelope and postcard's rules (docs/wire-format.md) it is enough to decode a payload
//! without this crate: tests/python/test_mcap_decoder.py decodes whole recordings from it.

use serde_json::{json, Value};
use serde_reflection::{Format, FormatHolder, Registry, Tracer, TracerConfig};

use super::{
    AccCommand, AccMode, AccStatus, AccWarning, CameraFrame, CameraInfo, ControlCommand, Detections,
    GroundTruthObjects, Header, ImageEncoding, MessageKind, ObjectClass, RoadSpec, SimClock, SimEvent, SimEventKind,
    SimMode, Speed, VehicleState, WIRE_VERSION,
};

/// The name of the schema encoding whose data [`schema_data`] makes (docs/recording.md).
pub const SCHEMA_ENCODING: &str = "slipstream-layout";

/// The schema data of a message type: JSON with the envelope (wire version, kind byte), the
/// message type's name, the names of the header's and body's types (the body's is the Rust
/// type's: `RoadSpec` for the RoadMap message), and the registry of every type they use.
pub fn schema_data(kind: MessageKind) -> Value {
    let (body, registry) = trace(kind);
    json!({
        "format": "serde-reflection registry; values in postcard (docs/wire-format.md)",
        "wire_version": WIRE_VERSION,
        "kind": kind as u8,
        "name": kind.name(),
        "envelope": ["u8 wire_version", "u8 kind", "header", "body"],
        "header": "Header",
        "body": body,
        "registry": serde_json::to_value(&registry).unwrap_or(Value::Null),
    })
}

/// The body type's name and the registry of the header, the body and the types they use.
fn trace(kind: MessageKind) -> (String, Registry) {
    let mut tracer = Tracer::new(TracerConfig::default());
    // Plain data types with derived serde impls: tracing them cannot fail (a test traces all).
    let body = trace_body(&mut tracer, kind).unwrap_or_else(|e| format!("untraceable: {e}"));
    // An enum inside a struct is traced one variant at a time: each enum on its own first,
    // so that every variant is known.
    let _ = tracer.trace_simple_type::<Header>();
    let _ = tracer.trace_simple_type::<AccMode>();
    let _ = tracer.trace_simple_type::<AccWarning>();
    let _ = tracer.trace_simple_type::<ImageEncoding>();
    let _ = tracer.trace_simple_type::<ObjectClass>();
    let _ = tracer.trace_simple_type::<SimMode>();
    let _ = tracer.trace_simple_type::<SimEventKind>();
    let _ = trace_body(&mut tracer, kind);
    let registry = tracer.registry().unwrap_or_default();
    (body.clone(), reachable(registry, &[body, "Header".to_string()]))
}

/// Traces the body type of `kind`; its name.
fn trace_body(tracer: &mut Tracer, kind: MessageKind) -> Result<String, serde_reflection::Error> {
    use MessageKind as K;
    let format = match kind {
        K::Speed => tracer.trace_simple_type::<Speed>()?.0,
        K::VehicleState => tracer.trace_simple_type::<VehicleState>()?.0,
        K::ControlCommand => tracer.trace_simple_type::<ControlCommand>()?.0,
        K::CameraFrame => tracer.trace_simple_type::<CameraFrame>()?.0,
        K::CameraInfo => tracer.trace_simple_type::<CameraInfo>()?.0,
        K::GroundTruthObjects => tracer.trace_simple_type::<GroundTruthObjects>()?.0,
        K::Detections => tracer.trace_simple_type::<Detections>()?.0,
        K::SimClock => tracer.trace_simple_type::<SimClock>()?.0,
        K::SimEvent => tracer.trace_simple_type::<SimEvent>()?.0,
        K::AccStatus => tracer.trace_simple_type::<AccStatus>()?.0,
        K::AccCommand => tracer.trace_simple_type::<AccCommand>()?.0,
        K::RoadMap => tracer.trace_simple_type::<RoadSpec>()?.0,
        K::EgoInfo => tracer.trace_simple_type::<super::EgoInfo>()?.0,
    };
    Ok(match format {
        Format::TypeName(name) => name,
        other => format!("{other:?}"),
    })
}

/// The part of `registry` that `roots` name, directly or through the types they use.
fn reachable(registry: Registry, roots: &[String]) -> Registry {
    let mut keep = std::collections::BTreeSet::new();
    let mut todo: Vec<String> = roots.to_vec();
    while let Some(name) = todo.pop() {
        let Some(container) = registry.get(&name) else { continue };
        if !keep.insert(name) {
            continue;
        }
        let mut named = Vec::new();
        let _ = container.visit(&mut |f: &Format| {
            if let Format::TypeName(n) = f {
                named.push(n.clone());
            }
            Ok(())
        });
        todo.extend(named);
    }
    registry.into_iter().filter(|(name, _)| keep.contains(name)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_traces_with_its_header_and_every_type_it_names() {
        for kind in MessageKind::ALL {
            let data = schema_data(kind);
            let registry = data["registry"].as_object().unwrap_or_else(|| panic!("{kind:?}: no registry"));
            let body = data["body"].as_str().unwrap();
            assert!(registry.contains_key(body), "{kind:?}: {body} not in {:?}", registry.keys());
            assert!(registry.contains_key("Header"), "{kind:?}");
            // Every type a field names is itself in the registry.
            let text = data["registry"].to_string();
            for (at, _) in text.match_indices("{\"TYPENAME\":\"") {
                let name: String = text[at + 13..].chars().take_while(|c| *c != '"').collect();
                assert!(registry.contains_key(&name), "{kind:?}: {name} is named but not described");
            }
        }
    }

    #[test]
    fn the_header_lists_its_fields_in_wire_order() {
        let data = schema_data(MessageKind::Speed);
        let fields: Vec<String> = data["registry"]["Header"]["STRUCT"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|f| f.as_object().unwrap().keys().cloned())
            .collect();
        assert_eq!(fields, ["seq", "stamp_sim_ns", "stamp_pub_ns"]);
    }
}
