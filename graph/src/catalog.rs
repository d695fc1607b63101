//! The signature of a node kind as the static checker sees it, and the catalog that holds them.
//! The runtime's node registry implements [`Catalog`]; tests can build one from plain data.

use crate::ports::TypeSet;
use serde::Serialize;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DevicePreference {
    Cpu,
    Gpu,
}

#[derive(Clone, Debug, Serialize)]
pub struct InputSpec {
    pub name: String,
    #[serde(rename = "type")]
    pub ty: TypeSet,
    pub required: bool,
    pub doc: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct OutputSpec {
    pub name: String,
    #[serde(rename = "type")]
    pub ty: String,
    pub doc: String,
}

/// Everything the checker, the `nodes` listing and the JSON Schema export need about a kind.
#[derive(Clone, Debug, Serialize)]
pub struct KindSignature {
    pub kind: String,
    pub version: u32,
    pub device: DevicePreference,
    pub doc: String,
    pub inputs: Vec<InputSpec>,
    pub outputs: Vec<OutputSpec>,
    /// JSON Schema of the parameter object, with defaults.
    pub params: serde_json::Value,
    /// Timings the kind reports in the run report (not outputs: they are not cached).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub timings: Vec<OutputSpec>,
}

impl KindSignature {
    pub fn input(&self, name: &str) -> Option<&InputSpec> {
        self.inputs.iter().find(|p| p.name == name)
    }

    pub fn output(&self, name: &str) -> Option<&OutputSpec> {
        self.outputs.iter().find(|p| p.name == name)
    }

    /// Parameters without a default (the schema's `required`).
    pub fn required_params(&self) -> Vec<&str> {
        self.params
            .get("required")
            .and_then(serde_json::Value::as_array)
            .map(|r| r.iter().filter_map(serde_json::Value::as_str).collect())
            .unwrap_or_default()
    }
}

/// A set of node kinds, looked up by name.
pub trait Catalog {
    fn signature(&self, kind: &str) -> Option<&KindSignature>;
    fn kinds(&self) -> Vec<&str>;
    /// Checks parameters that passed the schema against what the kind will really accept (its
    /// typed parameter struct and its own checks), so that `validate` refuses everything `run`
    /// would. Catalogs of plain signatures accept all.
    fn check_typed(
        &self,
        _kind: &str,
        _params: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<(), TypedProblem> {
        Ok(())
    }
}

/// Why a kind refused its parameters: the parameter when the kind's check named it (a rule
/// between parameters names the one to change), else only a message (a value the struct cannot
/// hold, which the checker then traces to its parameter).
#[derive(Clone, Debug, PartialEq)]
pub struct TypedProblem {
    pub param: Option<String>,
    pub message: String,
}

impl Catalog for Vec<KindSignature> {
    fn signature(&self, kind: &str) -> Option<&KindSignature> {
        self.iter().find(|s| s.kind == kind)
    }

    fn kinds(&self) -> Vec<&str> {
        self.iter().map(|s| s.kind.as_str()).collect()
    }
}
