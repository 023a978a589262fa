//! The scenario file's shape.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use cantwin_can::BitRate;
use serde::Deserialize;
use toml::Spanned;

use crate::error::{Located, ScenarioError, line_of};
use crate::spec::{BusSpec, DeviceSpec};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    name: Option<String>,
    description: Option<String>,
    seed: Option<u64>,
    #[serde(default)]
    bus: Vec<Spanned<RawBus>>,
    #[serde(default)]
    device: Vec<Spanned<BTreeMap<String, Spanned<toml::Value>>>>,
    check: Option<crate::script::parse::RawCheck>,
    #[serde(default)]
    at: Vec<Spanned<crate::script::parse::RawAt>>,
    #[serde(default)]
    expect: Vec<Spanned<crate::script::parse::RawExpect>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBus {
    name: Spanned<String>,
    bit_rate: Spanned<String>,
}

/// A parsed, checked scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// The file it came from (for error messages).
    pub file: PathBuf,
    /// A short name.
    pub name: String,
    /// What it shows.
    pub description: String,
    /// Seed of every bus's fault injection generator.
    pub seed: u64,
    /// The buses, in file order.
    pub buses: Vec<BusSpec>,
    /// The devices, in file order.
    pub devices: Vec<DeviceSpec>,
    /// Timed stimuli and expectations (`[[at]]`, `[[expect]]`, `[check]`), run by
    /// `cantwin sim --check`.
    pub script: crate::script::parse::Script,
}

impl Scenario {
    /// Read and check a scenario file.
    pub fn load(path: impl AsRef<Path>) -> Result<Scenario, ScenarioError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Io {
            file: path.to_path_buf(),
            source,
        })?;
        Scenario::parse(&text, path)
    }

    /// Parse and check scenario text; `file` names it in errors.
    pub fn parse(text: &str, file: impl AsRef<Path>) -> Result<Scenario, ScenarioError> {
        let file = file.as_ref().to_path_buf();
        let at = |line: Option<usize>, key: Option<String>| Located {
            file: file.clone(),
            line,
            key,
        };
        let raw: RawScenario = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| line_of(text, s.start));
            ScenarioError::Syntax {
                at: at(line, None),
                message: e.message().trim_end().to_string(),
            }
        })?;
        if raw.bus.is_empty() {
            return Err(ScenarioError::Invalid {
                at: at(None, Some("bus".into())),
                message: "a scenario needs at least one [[bus]] table".into(),
            });
        }
        let mut buses: Vec<BusSpec> = Vec::new();
        for (i, b) in raw.bus.iter().enumerate() {
            let b_line = line_of(text, b.span().start);
            let b = b.get_ref();
            let name = b.name.get_ref().trim().to_string();
            let name_line = line_of(text, b.name.span().start);
            if name.is_empty()
                || name.len() > 64
                || name
                    .chars()
                    .any(|c| c.is_whitespace() || c == '<' || c == '>')
            {
                return Err(ScenarioError::Invalid {
                    at: at(Some(name_line), Some(format!("bus[{i}].name"))),
                    message: format!(
                        "bus name {name:?} must be 1–64 characters without spaces or angle brackets (it is a socketcand channel name)"
                    ),
                });
            }
            if buses.iter().any(|x| x.name == name) {
                return Err(ScenarioError::Invalid {
                    at: at(Some(name_line), Some(format!("bus[{i}].name"))),
                    message: format!("a bus named {name:?} is already defined"),
                });
            }
            let bit_rate =
                b.bit_rate
                    .get_ref()
                    .parse::<BitRate>()
                    .map_err(|e| ScenarioError::Invalid {
                        at: at(
                            Some(line_of(text, b.bit_rate.span().start)),
                            Some(format!("bus[{i}].bit_rate")),
                        ),
                        message: e.to_string(),
                    })?;
            buses.push(BusSpec {
                name,
                bit_rate,
                line: b_line,
            });
        }
        let mut devices: Vec<DeviceSpec> = Vec::new();
        for (i, d) in raw.device.iter().enumerate() {
            let line = line_of(text, d.span().start);
            let mut settings: BTreeMap<String, (toml::Value, usize)> = d
                .get_ref()
                .iter()
                .map(|(k, v)| {
                    (
                        k.clone(),
                        (v.get_ref().clone(), line_of(text, v.span().start)),
                    )
                })
                .collect();
            let mut take_str = |key: &str| -> Result<(String, usize), ScenarioError> {
                match settings.remove(key) {
                    Some((toml::Value::String(s), l)) => Ok((s, l)),
                    Some((_, l)) => Err(ScenarioError::Invalid {
                        at: at(Some(l), Some(format!("device[{i}].{key}"))),
                        message: format!("`{key}` must be a string"),
                    }),
                    None => Err(ScenarioError::Invalid {
                        at: at(Some(line), Some(format!("device[{i}].{key}"))),
                        message: format!("every [[device]] needs `{key}`"),
                    }),
                }
            };
            let (name, name_line) = take_str("name")?;
            let (kind, _) = take_str("kind")?;
            let (bus, bus_line) = take_str("bus")?;
            if devices.iter().any(|x| x.name == name) {
                return Err(ScenarioError::Invalid {
                    at: at(Some(name_line), Some(format!("device[{i}].name"))),
                    message: format!("a device named {name:?} is already defined"),
                });
            }
            if !buses.iter().any(|b| b.name == bus) {
                let known: Vec<&str> = buses.iter().map(|b| b.name.as_str()).collect();
                return Err(ScenarioError::Invalid {
                    at: at(Some(bus_line), Some(format!("device[{i}].bus"))),
                    message: format!("no bus named {bus:?} (buses: {})", known.join(", ")),
                });
            }
            devices.push(DeviceSpec {
                name,
                kind,
                bus,
                index: i,
                line,
                settings,
            });
        }
        let script = crate::script::parse::ScriptParser {
            text,
            file: &file,
            buses: &buses,
            devices: &devices,
        }
        .parse(raw.check.as_ref(), &raw.at, &raw.expect)?;
        Ok(Scenario {
            script,
            name: raw.name.unwrap_or_else(|| {
                file.file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "scenario".into())
            }),
            description: raw.description.unwrap_or_default(),
            seed: raw.seed.unwrap_or(0),
            file,
            buses,
            devices,
        })
    }

    /// The bus named `name`.
    pub fn bus(&self, name: &str) -> Option<&BusSpec> {
        self.buses.iter().find(|b| b.name == name)
    }
}
