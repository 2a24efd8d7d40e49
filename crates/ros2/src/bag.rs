//! A `ros2`-profile MCAP file, as rosbag2 writes one: a channel per ROS topic with message
//! encoding `cdr`, its schema the type's complete `ros2msg` definition (dependencies
//! included). `ros2 bag play`, Foxglove and mcap-ros2-support read it.
//!
//! Per message: log time is when the message was taken (received, or as recorded), publish
//! time the bus publisher's stamp, sequence the bus header's seq (its low 32 bits).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use parking_lot::Mutex;

use super::mapping::{Direction, Ros2Config, Route};
use super::outlet::Outlet;
use super::schema;
use slipstream_contract::msg::Header;

/// The profile and encodings of the ROS 2 MCAP convention.
pub const PROFILE: &str = "ros2";
pub(crate) const MESSAGE_ENCODING: &str = "cdr";
pub const SCHEMA_ENCODING: &str = "ros2msg";

struct Open {
    writer: mcap::Writer<BufWriter<File>>,
    channels: BTreeMap<Route, u16>,
    schemas: BTreeMap<String, u16>,
    messages: u64,
}

/// An open ROS 2 recording.
pub struct Bag {
    path: PathBuf,
    /// Route -> (ROS name, type).
    routes: BTreeMap<Route, (String, String)>,
    open: Mutex<Option<Open>>,
}

impl Bag {
    /// Creates `path` for the routes of `config` that are on (names resolved under its
    /// namespace).
    pub fn create(path: &Path, config: &Ros2Config) -> Result<Bag> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(Error::file("create", dir))?;
        }
        let file = File::create(path).map_err(Error::file("create", path))?;
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Lz4))
            .profile(PROFILE)
            .library(format!("slipstream {}", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(Error::mcap("start", path))?;
        let node = config.node_id(String::new());
        let routes = config
            .enabled()
            .filter(|(r, _)| r.direction() == Direction::ToRos)
            .map(|(r, e)| (r, (node.resolve(&e.name), e.type_name.clone())))
            .collect();
        let open = Open { writer, channels: BTreeMap::new(), schemas: BTreeMap::new(), messages: 0 };
        Ok(Bag { path: path.to_path_buf(), routes, open: Mutex::new(Some(open)) })
    }

    /// Writes one message of `route` taken at `log_time_ns`.
    pub fn write(&self, route: Route, header: &Header, log_time_ns: u64, cdr: &[u8]) -> Result<()> {
        let Some((topic, type_name)) = self.routes.get(&route) else { return Ok(()) };
        let mut guard = self.open.lock();
        let closed = || Error::Recording { path: self.path.clone(), problem: "is closed".into() };
        let open = guard.as_mut().ok_or_else(closed)?;
        let fail = |e: mcap::McapError| Error::mcap("write", &self.path)(e);
        let channel = match open.channels.get(&route) {
            Some(id) => *id,
            None => {
                let schema = match open.schemas.get(type_name) {
                    Some(id) => *id,
                    None => {
                        let text = schema::ros2msg(type_name)?;
                        let id = open.writer.add_schema(type_name, SCHEMA_ENCODING, text.as_bytes()).map_err(fail)?;
                        open.schemas.insert(type_name.clone(), id);
                        id
                    }
                };
                let id = open.writer.add_channel(schema, topic, MESSAGE_ENCODING, &BTreeMap::new()).map_err(fail)?;
                open.channels.insert(route, id);
                id
            }
        };
        let record = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: header.seq as u32,
            log_time: log_time_ns,
            publish_time: header.stamp_pub_ns,
        };
        open.writer.write_to_known_channel(&record, cdr).map_err(fail)?;
        open.messages += 1;
        Ok(())
    }

    /// Writes the index and closes the file; the messages written.
    pub fn finish(&self) -> Result<u64> {
        let Some(mut open) = self.open.lock().take() else { return Ok(0) };
        open.writer.finish().map_err(Error::mcap("finish", &self.path))?;
        Ok(open.messages)
    }
}

impl Outlet for Bag {
    fn put(&self, route: Route, header: &Header, cdr: Vec<u8>) -> Result<()> {
        self.write(route, header, slipstream_contract::msg::wall_clock_ns(), &cdr)
    }

    fn routes(&self) -> Vec<(Route, String, String)> {
        self.routes.iter().map(|(r, (topic, ty))| (*r, topic.clone(), ty.clone())).collect()
    }
}

impl Drop for Bag {
    fn drop(&mut self) {
        if let Err(e) = self.finish() {
            tracing::warn!("{e:#}");
        }
    }
}
