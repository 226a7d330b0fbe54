//! A library and its file: a versioned header, the scene and settings it was built with, the controllers,
//! and a checksum. The layout (little-endian):
//!
//! ```text
//! b"SLCPLIB\0" | version: u32 | payload length: u64 | CRC-32 of the payload: u32 | payload
//! ```
//!
//! with the payload the `bincode` (2, standard configuration) encoding of the scene (as its TOML text),
//! the task it was built for (its name and its table of the scene file), the settings and the
//! controllers. Loading checks all of it before anything is decoded, then the decoded
//! library for consistency; a file that fails any check is refused whole.

use crate::build::{Entries, LibrarySettings, build_entries};
use crate::entry::Entry;
use crate::error::LibraryError;
use crate::policy::Policy;
use dynamics::{Scene, SceneSpec};
use serde::{Deserialize, Serialize};
use std::path::Path;
use task::Progress;
use task::{ProblemFile, Task, TaskSpec};

/// The file's magic bytes.
pub const MAGIC: &[u8; 8] = b"SLCPLIB\0";
/// The format version this build writes and reads.
pub const VERSION: u32 = 9;
const HEADER: usize = 8 + 4 + 8 + 4;

/// A trajectory library: the scene and settings it was built with and its local controllers.
#[derive(Debug, Clone, PartialEq)]
pub struct Library {
    scene: Scene,
    /// The task of the scene file it was built for, checked against the scene, with its table as the
    /// file gave it.
    task: (Task, TaskSpec),
    /// How it was built.
    pub settings: LibrarySettings,
    /// The controllers, in the order they were built.
    pub entries: Vec<Entry>,
}

#[derive(Serialize, Deserialize)]
struct Payload {
    scene_toml: String,
    /// The task's name and its table from the scene file.
    task: (String, TaskSpec),
    settings: LibrarySettings,
    entries: Vec<Entry>,
}

/// The first place two scene descriptions differ: its path (`body[1].joint.limits`, `contact[0].friction`)
/// and the two values (`missing` where one has none).
fn first_difference(
    a: &toml::Value,
    b: &toml::Value,
    path: String,
) -> Option<(String, String, String)> {
    use toml::Value;
    let show = |v: Option<&Value>| v.map_or("missing".to_string(), |v| v.to_string());
    match (a, b) {
        (Value::Table(x), Value::Table(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            keys.into_iter().find_map(|k| {
                let here = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                match (x.get(k), y.get(k)) {
                    (Some(p), Some(q)) => first_difference(p, q, here),
                    (p, q) => Some((here, show(p), show(q))),
                }
            })
        }
        (Value::Array(x), Value::Array(y)) => {
            let found = x
                .iter()
                .zip(y)
                .enumerate()
                .find_map(|(i, (p, q))| first_difference(p, q, format!("{path}[{i}]")));
            found.or_else(|| {
                (x.len() != y.len()).then(|| {
                    (
                        format!("{path} (its length)"),
                        x.len().to_string(),
                        y.len().to_string(),
                    )
                })
            })
        }
        _ if a == b => None,
        _ => Some((path, a.to_string(), b.to_string())),
    }
}

/// How many bytes bincode may claim per byte of payload: it claims each primitive at its size in memory,
/// and an integer of 8 bytes (a count, a length) may be encoded in one (a varint).
const CLAIM_PER_BYTE: usize = 8;

/// Decode a payload with bincode's byte limit set to the smallest power of two at least
/// [`CLAIM_PER_BYTE`] times the payload's size: bincode claims every primitive at its size in memory
/// (a `u64` counted as 8 bytes where its varint took 1), so a limit of the payload's size alone refused
/// files it had just written whose payload sat a little below a power of two. Every length prefix is
/// claimed against the limit before anything is allocated, so no prefix (a crafted 2^62, say) can
/// allocate more than twice that bound; past the limit it is an error.
fn decode_bounded(body: &[u8]) -> Result<(Payload, usize), bincode::error::DecodeError> {
    fn with<const LIMIT: usize>(
        body: &[u8],
    ) -> Result<(Payload, usize), bincode::error::DecodeError> {
        bincode::serde::decode_from_slice(body, bincode::config::standard().with_limit::<LIMIT>())
    }
    macro_rules! ladder {
        ($($bits:literal)*) => {
            match body
                .len()
                .max(1)
                .saturating_mul(CLAIM_PER_BYTE)
                .checked_next_power_of_two()
                .map_or(u32::MAX, usize::trailing_zeros)
            {
                $(b if b <= $bits => with::<{ 1usize << $bits }>(body),)*
                _ => Err(bincode::error::DecodeError::LimitExceeded),
            }
        };
    }
    ladder!(12 14 16 18 20 22 24 26 28 30 32 34 36 38 40)
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> LibraryError + '_ {
    move |source| LibraryError::Io {
        path: path.display().to_string(),
        source,
    }
}

impl Library {
    /// Build a library (paper section IV-C) for the task `name` of a scene file (its only one when
    /// `None`; [`ProblemFile::builtin`] for the paper's finger): its cost, control limits, periodic
    /// coordinate and success criterion; `settings` as [`LibrarySettings::for_task`] makes them (their
    /// `model`, `h`, `horizon` and `x0` are the ones used; an empty `x0` is the task's). `progress` sees
    /// each controller as it is added.
    pub fn build(
        problem: &ProblemFile,
        name: Option<&str>,
        settings: &LibrarySettings,
        progress: impl FnMut(usize, &Entry) + Send,
    ) -> Result<Self, LibraryError> {
        let task = problem.task(name)?;
        let built = build_entries(&problem.scene, &task, settings, progress)?;
        Ok(Library::assemble(problem, task, settings, built))
    }

    /// The library of `built`, made for `task` of `problem` with `settings` (its horizon the one the
    /// build used).
    pub(crate) fn assemble(
        problem: &ProblemFile,
        task: Task,
        settings: &LibrarySettings,
        built: Entries,
    ) -> Self {
        let spec = problem.tasks[&task.name].clone();
        Library {
            scene: problem.scene.clone(),
            task: (task, spec),
            settings: LibrarySettings {
                horizon: built.horizon,
                ..settings.clone()
            },
            entries: built.entries,
        }
    }

    /// The scene it was built for.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The task it was built for.
    pub fn task(&self) -> &Task {
        &self.task.0
    }

    /// The start of its first trajectory: the settings' `x0`, or its task's when that is empty.
    pub fn x0(&self) -> &[f64] {
        crate::start(&self.settings.x0, &self.task.0.x0)
    }

    /// The cost its trajectories minimise (its task's).
    pub fn cost(&self) -> &task::TaskCost {
        &self.task.0.cost
    }

    /// The angles its policy compares modulo a turn, each with the turn (its task's
    /// [`task::Task::turn_symmetries`] in its scene).
    pub fn turn_symmetries(&self) -> Vec<(usize, f64)> {
        self.task().turn_symmetries(&self.scene)
    }

    /// The periodic coordinate its policy compares states modulo, and the direction its task rewards.
    pub fn progress(&self) -> Result<Progress, LibraryError> {
        Ok(Progress::of_task(self.task())?)
    }

    /// The global policy (eq. 20) over its controllers, saturated to its task's control limits, charging
    /// laws for controls beyond the stored range at its task's control weight, at the library's time
    /// step ([`Policy::with_time_step`]: another world's step is the caller's to set).
    pub fn policy(&self) -> Result<Policy, LibraryError> {
        let s = &self.scene;
        Policy::for_task(
            &self.entries,
            s.n_state(),
            s.n_controls,
            &self.progress()?,
            &self.turn_symmetries(),
        )?
        .with_neighbours(self.settings.neighbours)?
        .with_limits(self.task().control_limits.clone())?
        .with_control_weight(self.cost().control_weight)?
        .with_time_step(self.settings.h)
    }

    /// What counts as success for its task ([`task::Success`]).
    pub fn success(&self) -> &task::Success {
        &self.task().success
    }

    /// `Err` unless the library was built for `scene`.
    pub fn check_scene(&self, scene: &Scene) -> Result<(), LibraryError> {
        if self.scene.spec() != scene.spec() {
            let value = |s: &Scene| toml::Value::try_from(s.spec()).ok();
            let what = match (value(&self.scene), value(scene)) {
                (Some(built), Some(used)) => {
                    first_difference(&built, &used, String::new()).map(|(path, b, u)| {
                        format!("{path} is {b} in the library's scene and {u} in this one")
                    })
                }
                _ => None,
            };
            return Err(LibraryError::SceneMismatch(what.unwrap_or_else(|| {
                format!(
                    "built for {} bodies and {} contact pairs, used with {} and {}",
                    self.scene.spec().bodies.len(),
                    self.scene.spec().contacts.len(),
                    scene.spec().bodies.len(),
                    scene.spec().contacts.len()
                )
            })));
        }
        Ok(())
    }

    /// The file's bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, LibraryError> {
        let payload = Payload {
            scene_toml: toml::to_string(self.scene.spec())
                .map_err(|e| LibraryError::Invalid(format!("the scene does not serialise: {e}")))?,
            task: (self.task.0.name.clone(), self.task.1.clone()),
            settings: self.settings.clone(),
            entries: self.entries.clone(),
        };
        let body = bincode::serde::encode_to_vec(&payload, bincode::config::standard())
            .map_err(|e| LibraryError::Invalid(format!("encoding: {e}")))?;
        let mut out = Vec::with_capacity(HEADER + body.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(body.len() as u64).to_le_bytes());
        out.extend_from_slice(&crc32fast::hash(&body).to_le_bytes());
        out.extend_from_slice(&body);
        Ok(out)
    }

    /// Decode and check a library file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, LibraryError> {
        if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
            return Err(LibraryError::NotALibrary);
        }
        if bytes.len() < HEADER {
            return Err(LibraryError::Truncated {
                expected: HEADER as u64,
                found: bytes.len() as u64,
            });
        }
        let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
        let version = word(8);
        if version != VERSION {
            return Err(LibraryError::Version {
                found: version,
                expected: VERSION,
            });
        }
        let length = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes"));
        let body = &bytes[HEADER..];
        if (body.len() as u64) != length {
            return Err(if (body.len() as u64) < length {
                LibraryError::Truncated {
                    expected: length,
                    found: body.len() as u64,
                }
            } else {
                LibraryError::Invalid(format!(
                    "{} bytes after the payload",
                    body.len() as u64 - length
                ))
            });
        }
        let expected = word(20);
        let found = crc32fast::hash(body);
        if found != expected {
            return Err(LibraryError::Corrupt { expected, found });
        }
        let (payload, used) =
            decode_bounded(body).map_err(|e| LibraryError::Invalid(format!("decoding: {e}")))?;
        if used != body.len() {
            return Err(LibraryError::Invalid(
                "trailing bytes in the payload".into(),
            ));
        }
        let spec: SceneSpec = toml::from_str(&payload.scene_toml)
            .map_err(|e| LibraryError::Invalid(format!("its scene: {e}")))?;
        let scene = Scene::new(spec)?;
        payload.settings.validate(&scene)?;
        let (name, spec) = payload.task;
        let task = (Task::new(&scene, &name, &spec)?, spec);
        let library = Library {
            scene,
            task,
            settings: payload.settings,
            entries: payload.entries,
        };
        // Sizes and finiteness of every controller.
        library.policy()?;
        Ok(library)
    }

    /// Write the library to `path` (through a temporary file of a fresh name beside it, renamed into place,
    /// so that a crash never leaves half a library under the name and no other file is touched; the
    /// temporary file is removed if anything fails).
    pub fn save(&self, path: &Path) -> Result<(), LibraryError> {
        write_atomically(path, &self.to_bytes()?)
    }

    /// Check, before a long build, that [`Library::save`] could write `path`: not a directory, and a file
    /// can be created beside it (it is removed again).
    pub fn check_destination(path: &Path) -> Result<(), LibraryError> {
        if path.is_dir() {
            return Err(LibraryError::Io {
                path: path.display().to_string(),
                source: std::io::Error::new(std::io::ErrorKind::IsADirectory, "is a directory"),
            });
        }
        let (tmp, file) = temporary_beside(path)?;
        drop(file);
        std::fs::remove_file(&tmp).map_err(io(&tmp))
    }

    /// Read and check a library file.
    pub fn load(path: &Path) -> Result<Self, LibraryError> {
        let bytes = std::fs::read(path).map_err(io(path))?;
        Library::from_bytes(&bytes)
    }
}

/// Write `bytes` to `path` whole or not at all: through a temporary file of a fresh name beside it, synced
/// and renamed into place, so that a failed or interrupted write never leaves part of a file where a good
/// one was (the temporary file is removed if anything fails). Every file the project's commands write
/// goes through here.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), LibraryError> {
    if path.is_dir() {
        return Err(LibraryError::Io {
            path: path.display().to_string(),
            source: std::io::Error::new(std::io::ErrorKind::IsADirectory, "is a directory"),
        });
    }
    let (tmp, mut file) = temporary_beside(path)?;
    let written = std::io::Write::write_all(&mut file, bytes)
        .and_then(|()| file.sync_all())
        .map_err(io(&tmp))
        .and_then(|()| std::fs::rename(&tmp, path).map_err(io(path)));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// A new file beside `path` with a name no other file has (`.NAME.PID-N.partial`, created exclusively).
fn temporary_beside(path: &Path) -> Result<(std::path::PathBuf, std::fs::File), LibraryError> {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map_or("library".into(), |n| n.to_string_lossy().into_owned());
    loop {
        let k = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let tmp = dir.join(format!(".{name}.{}-{k}.partial", std::process::id()));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
        {
            Ok(file) => return Ok((tmp, file)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(io(&tmp)(e)),
        }
    }
}
