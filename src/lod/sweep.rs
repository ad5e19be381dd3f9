//! Parameter sweeps (`vkterrain eval --sweep KEY=v1,v2,...`): each method's settings type
//! declares one table of the settings it lets a sweep vary; the key is the setting's own name.

use crate::error::{Error, Result};

/// One sweepable setting of settings type `S`.
pub struct Sweep<S: 'static> {
    /// The setting's name (as in the config file).
    pub key: &'static str,
    pub help: &'static str,
    /// Sets the value (validated afterwards with the rest of the settings).
    pub apply: fn(&mut S, f64),
}

/// Applies `key = value` through `table`; an unknown key is an error.
pub fn apply<S>(table: &[Sweep<S>], settings: &mut S, key: &str, value: f64) -> Result<()> {
    let sweep = table
        .iter()
        .find(|s| s.key == key)
        .ok_or_else(|| Error::invalid("sweep", format!("unknown parameter {key:?}")))?;
    (sweep.apply)(settings, value);
    Ok(())
}

/// Parses `key=v1,v2,...`.
pub fn parse(text: &str) -> Result<(String, Vec<f64>)> {
    let bad = |m: &str| Error::invalid("sweep", format!("{text:?}: {m} (expected key=v1,v2,...)"));
    let (key, values) = text.split_once('=').ok_or_else(|| bad("no '='"))?;
    let values = values
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .map_err(|_| bad("a value is not a number"))
        })
        .collect::<Result<Vec<f64>>>()?;
    if values.is_empty() || values.iter().any(|v| !v.is_finite()) {
        return Err(bad("values must be finite numbers"));
    }
    Ok((key.trim().to_string(), values))
}
