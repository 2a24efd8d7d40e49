//! What ROS 2 needs to know about a message type, derived from its definition in
//! [`super::catalog`]: the DDS type name and the RIHS01 type hash of its data keys and
//! liveliness tokens, and the `ros2msg` text an MCAP recording carries as its schema.
//!
//! The hash is ROS 2's own (REP 2011): SHA-256 of the type description as JSON, computed by
//! hiroz-schema (ZettaScale's ROS 2 on Zenoh). A test checks every hash against rosbags, which
//! computes it independently (tests/python/test_ros2.py).

use std::collections::{BTreeMap, BTreeSet};
use std::sync::OnceLock;

use hiroz_schema::{FieldDescription, FieldTypeDescription, TypeDescription, TypeDescriptionMsg, TypeId};

use super::catalog::TYPES;
use crate::message_error::Ros2Error;

/// The separator between definitions in a `ros2msg` schema (as rosbag2 writes it).
const SEPARATOR: &str = "================================================================================";

/// ROS 2 distributions whose keys differ: Humble has no type hashes in its keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Distro {
    Humble,
    Jazzy,
}

impl Distro {
    /// The hash part of a key: RIHS01 from Iron on, a fixed word in Humble.
    pub(crate) fn hash_of(self, type_name: &str) -> Result<String, Ros2Error> {
        match self {
            Distro::Humble => Ok("TypeHashNotSupported".to_string()),
            Distro::Jazzy => type_hash(type_name),
        }
    }
}

/// One field of a definition.
#[derive(Debug, Clone, PartialEq)]
struct Field {
    name: String,
    /// `float64`, `string`, or a nested type's full name (`std_msgs/msg/Header`).
    base: String,
    /// None: one value; Some(None): a sequence; Some(Some(n)): an array of n.
    array: Option<Option<u64>>,
}

impl Field {
    fn nested(&self) -> Option<&str> {
        self.base.contains('/').then_some(self.base.as_str())
    }

    /// The field as a line of a `.msg` file (nested types as `package/Type`).
    fn line(&self) -> String {
        let base = match self.nested() {
            Some(full) => full.replace("/msg/", "/"),
            None => self.base.clone(),
        };
        let suffix = match self.array {
            None => String::new(),
            Some(None) => "[]".into(),
            Some(Some(n)) => format!("[{n}]"),
        };
        format!("{base}{suffix} {}", self.name)
    }

    fn description(&self) -> Result<FieldTypeDescription, Ros2Error> {
        let id = match self.base.as_str() {
            "bool" => TypeId::BOOL,
            "byte" => TypeId::BYTE,
            "int8" => TypeId::INT8,
            "uint8" => TypeId::UINT8,
            "int16" => TypeId::INT16,
            "uint16" => TypeId::UINT16,
            "int32" => TypeId::INT32,
            "uint32" => TypeId::UINT32,
            "int64" => TypeId::INT64,
            "uint64" => TypeId::UINT64,
            "float32" => TypeId::FLOAT32,
            "float64" => TypeId::FLOAT64,
            "string" => TypeId::STRING,
            _ if self.nested().is_some() => TypeId::NESTED_TYPE,
            other => return Err(definition(&format!("field `{}`", self.name), format!("unknown type `{other}`"))),
        };
        let (offset, capacity) = match self.array {
            None => (0, 0),
            Some(Some(n)) => (48, n),
            Some(None) => (144, 0),
        };
        Ok(FieldTypeDescription {
            type_id: id + offset,
            capacity,
            string_capacity: 0,
            nested_type_name: self.nested().unwrap_or_default().to_string(),
        })
    }
}

/// Parses one definition; `package` resolves bare nested names.
fn parse(full_name: &str, text: &str) -> Result<Vec<Field>, Ros2Error> {
    let package = full_name.split('/').next().unwrap_or_default();
    let mut fields = Vec::new();
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        let (ty, name) =
            line.split_once(' ').ok_or_else(|| definition(full_name, format!("`{line}` is not `type name`")))?;
        let (base, array) = match ty.split_once('[') {
            None => (ty, None),
            Some((base, "]")) => (base, Some(None)),
            Some((base, rest)) => {
                let n = rest
                    .trim_end_matches(']')
                    .parse()
                    .map_err(|_| definition(full_name, format!("bad array `{ty}`")))?;
                (base, Some(Some(n)))
            }
        };
        let base = if base.chars().next().is_some_and(|c| c.is_ascii_uppercase()) {
            format!("{package}/msg/{base}")
        } else if let Some((pkg, ty)) = base.split_once('/') {
            format!("{pkg}/msg/{ty}")
        } else {
            base.to_string()
        };
        fields.push(Field { name: name.trim().to_string(), base, array });
    }
    Ok(fields)
}

/// Every definition, parsed once.
fn table() -> &'static BTreeMap<&'static str, Vec<Field>> {
    static TABLE: OnceLock<BTreeMap<&'static str, Vec<Field>>> = OnceLock::new();
    TABLE.get_or_init(|| {
        TYPES.iter().map(|(name, text)| (*name, parse(name, text).unwrap_or_else(|e| panic!("catalog: {e}")))).collect()
    })
}

fn fields_of(name: &str) -> Result<&'static [Field], Ros2Error> {
    table().get(name).map(Vec::as_slice).ok_or_else(|| unknown(name))
}

fn unknown(name: &str) -> Ros2Error {
    Ros2Error::UnknownType { name: name.to_string(), known: known_types().join(", ") }
}

fn definition(type_name: &str, problem: String) -> Ros2Error {
    Ros2Error::Definition { type_name: type_name.to_string(), problem }
}

/// The types a mapping may name.
pub fn known_types() -> Vec<&'static str> {
    table().keys().copied().collect()
}

/// Every type `name` refers to, directly or not, sorted by name.
fn dependencies(name: &str) -> Result<BTreeSet<&'static str>, Ros2Error> {
    let mut found = BTreeSet::new();
    let mut todo = vec![name.to_string()];
    while let Some(next) = todo.pop() {
        for field in fields_of(&next)? {
            if let Some(nested) = field.nested() {
                let (key, _) = table().get_key_value(nested).ok_or_else(|| unknown(nested))?;
                if found.insert(*key) {
                    todo.push(nested.to_string());
                }
            }
        }
    }
    Ok(found)
}

fn description(name: &str) -> Result<TypeDescription, Ros2Error> {
    let fields = fields_of(name)?
        .iter()
        .map(|f| {
            Ok(FieldDescription { name: f.name.clone(), field_type: f.description()?, default_value: String::new() })
        })
        .collect::<Result<_, Ros2Error>>()?;
    Ok(TypeDescription { type_name: name.to_string(), fields })
}

/// The RIHS01 hash of `name`: `RIHS01_<64 hex digits>`.
pub fn type_hash(name: &str) -> Result<String, Ros2Error> {
    let referenced = dependencies(name)?.into_iter().map(description).collect::<Result<_, _>>()?;
    let msg = TypeDescriptionMsg { type_description: description(name)?, referenced_type_descriptions: referenced };
    Ok(hiroz_schema::calculate_hash(&msg).to_rihs_string())
}

/// The DDS name rmw_zenoh puts in keys: `sensor_msgs::msg::dds_::Image_`.
pub fn dds_name(name: &str) -> Result<String, Ros2Error> {
    fields_of(name)?;
    hiroz_schema::dds_from_canonical(name).ok_or_else(|| Ros2Error::BadTypeName(name.to_string()))
}

/// The complete `ros2msg` definition: the type's fields, then each type it refers to under
/// `MSG: package/Type`, as rosbag2 writes it into MCAP schemas.
pub fn ros2msg(name: &str) -> Result<String, Ros2Error> {
    let mut text = lines(name)?;
    for dep in dependencies(name)? {
        text.push_str(&format!("\n{SEPARATOR}\nMSG: {}\n{}", dep.replace("/msg/", "/"), lines(dep)?));
    }
    Ok(text)
}

fn lines(name: &str) -> Result<String, Ros2Error> {
    Ok(fields_of(name)?.iter().map(Field::line).collect::<Vec<_>>().join("\n"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_definition_parses_and_resolves() {
        for (name, _) in TYPES {
            dependencies(name).unwrap();
            assert!(type_hash(name).unwrap().starts_with("RIHS01_"));
        }
    }

    #[test]
    fn the_hash_of_a_type_follows_its_fields() {
        // builtin_interfaces Time and Duration have the same fields and differ only by name,
        // which the hash includes.
        assert_ne!(type_hash("builtin_interfaces/msg/Time"), type_hash("builtin_interfaces/msg/Duration"));
        assert_eq!(type_hash("rosgraph_msgs/msg/Clock"), type_hash("rosgraph_msgs/msg/Clock"));
    }

    #[test]
    fn schema_text_lists_each_dependency_once_under_its_short_name() {
        let text = ros2msg("nav_msgs/msg/Odometry").unwrap();
        assert!(text.starts_with("std_msgs/Header header\n"), "{text}");
        assert_eq!(text.matches("MSG: geometry_msgs/Pose\n").count(), 1, "{text}");
        assert!(text.contains("MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec"), "{text}");
        assert!(text.contains("float64[36] covariance"), "{text}");
    }

    #[test]
    fn dds_names_and_unknown_types() {
        assert_eq!(dds_name("sensor_msgs/msg/Image").unwrap(), "sensor_msgs::msg::dds_::Image_");
        let err = dds_name("sensor_msgs/msg/PointCloud2").unwrap_err();
        assert!(matches!(&err, Ros2Error::UnknownType { name, .. } if name == "sensor_msgs/msg/PointCloud2"), "{err}");
        assert!(err.to_string().contains("sensor_msgs/msg/Image"), "{err}");
        assert_eq!(Distro::Humble.hash_of("sensor_msgs/msg/Image").unwrap(), "TypeHashNotSupported");
    }
}
