//! Parsers for the command-line numbers that become durations, rates or step budgets, with upper
//! bounds: a typo (`--duration-s inf`, an extra zero or three) fails at the flag with a message that
//! names the value and the accepted range, instead of panicking or waiting forever later. Use them as
//! clap value parsers: `#[arg(long, value_parser = cli_values::seconds)]`.

/// Longest duration accepted for a `*-s` flag: 30 days.
pub const MAX_SECONDS: f64 = 30.0 * 24.0 * 3600.0;
/// Longest interval accepted for a `*-ms` flag: one hour.
pub const MAX_MILLIS: u64 = 3_600_000;
/// Largest speed factor accepted by `bag play --rate`.
pub const MAX_RATE: f64 = 1000.0;
/// Smallest positive speed factor accepted by `bag play --rate` (a second of the bag in about 17
/// minutes); 0 means as fast as possible.
pub const MIN_RATE: f64 = 0.001;
/// Largest step budget accepted by the policy's flow control (`--max-lead`, `--steps-per-update`).
pub const MAX_STEPS: u64 = 1_000_000;

/// A command-line number refused: it does not parse, or it is outside the range the flag accepts.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BadValue {
    /// Not a number of the expected kind.
    #[error("'{given}' is not a {kind}")]
    NotANumber {
        /// The text given.
        given: String,
        /// What was expected, e.g. `whole number of ms`.
        kind: String,
    },
    /// A number outside the flag's range.
    #[error("{given} is outside {range}")]
    OutOfRange {
        /// The value with its unit, e.g. `0 ms`.
        given: String,
        /// The accepted range with its meaning, e.g. `1..=3600000`.
        range: String,
    },
}

/// A duration in seconds: finite, above 0, at most [`MAX_SECONDS`].
pub fn seconds(s: &str) -> Result<f64, BadValue> {
    let v = number(s, "number of seconds")?;
    if v > 0.0 && v <= MAX_SECONDS {
        Ok(v)
    } else {
        Err(BadValue::OutOfRange { given: format!("{s} s"), range: format!("(0, {MAX_SECONDS}] (30 days)") })
    }
}

/// A duration in minutes: finite, above 0, at most [`MAX_SECONDS`] / 60.
pub fn positive_minutes(s: &str) -> Result<f64, BadValue> {
    let v = number(s, "number of minutes")?;
    if v > 0.0 && v <= MAX_SECONDS / 60.0 {
        Ok(v)
    } else {
        Err(BadValue::OutOfRange { given: format!("{s} min"), range: format!("(0, {}] (30 days)", MAX_SECONDS / 60.0) })
    }
}

/// A whole number of seconds: 1 ..= [`MAX_SECONDS`].
pub fn whole_seconds(s: &str) -> Result<u64, BadValue> {
    bounded(s, "s", 1, MAX_SECONDS as u64)
}

/// An interval in milliseconds: 1 ..= [`MAX_MILLIS`].
pub fn millis(s: &str) -> Result<u64, BadValue> {
    bounded(s, "ms", 1, MAX_MILLIS)
}

/// An interval in milliseconds that may be 0 (no wait): 0 ..= [`MAX_MILLIS`].
pub fn millis_or_zero(s: &str) -> Result<u64, BadValue> {
    bounded(s, "ms", 0, MAX_MILLIS)
}

/// A speed factor: 0 (as fast as possible), or [`MIN_RATE`] ..= [`MAX_RATE`] (a tiny positive
/// rate would stretch the bag's gaps past what a duration holds).
pub fn rate(s: &str) -> Result<f64, BadValue> {
    let v = number(s, "number")?;
    if v == 0.0 || (MIN_RATE..=MAX_RATE).contains(&v) {
        Ok(v)
    } else {
        Err(BadValue::OutOfRange {
            given: format!("rate {s}"),
            range: format!("[{MIN_RATE}, {MAX_RATE}] (or 0: as fast as possible)"),
        })
    }
}

/// A number that parses; NaN and the infinities come back as `NaN`, which no range contains.
fn number(s: &str, what: &str) -> Result<f64, BadValue> {
    let v: f64 = s.trim().parse().map_err(|_| BadValue::NotANumber { given: s.to_string(), kind: what.to_string() })?;
    Ok(if v.is_finite() { v } else { f64::NAN })
}

/// A step budget: 0 ..= [`MAX_STEPS`].
pub fn steps(s: &str) -> Result<u64, BadValue> {
    bounded(s, "steps", 0, MAX_STEPS)
}

/// A step count that must be at least 1: 1 ..= [`MAX_STEPS`].
pub fn positive_steps(s: &str) -> Result<u64, BadValue> {
    bounded(s, "steps", 1, MAX_STEPS)
}

/// An update count that must be at least 1: 1 ..= [`MAX_STEPS`].
pub fn positive_updates(s: &str) -> Result<u64, BadValue> {
    bounded(s, "updates", 1, MAX_STEPS)
}

/// An episode count that must be at least 1: 1 ..= [`MAX_STEPS`].
pub fn positive_episodes(s: &str) -> Result<u64, BadValue> {
    bounded(s, "episodes", 1, MAX_STEPS)
}

/// A whole number in `min ..= max` (`unit` only words the error).
pub fn bounded(s: &str, unit: &str, min: u64, max: u64) -> Result<u64, BadValue> {
    let v: u64 = s
        .trim()
        .parse()
        .map_err(|_| BadValue::NotANumber { given: s.to_string(), kind: format!("whole number of {unit}") })?;
    if (min..=max).contains(&v) {
        Ok(v)
    } else {
        Err(BadValue::OutOfRange { given: format!("{v} {unit}"), range: format!("{min}..={max}") })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_and_rates_outside_their_ranges_are_refused_with_the_range() {
        assert_eq!(seconds("2.5"), Ok(2.5));
        for bad in ["inf", "NaN", "-1", "0", "1e12", "ten"] {
            let e = seconds(bad).unwrap_err().to_string();
            assert!(e.contains(bad) || e.contains("number"), "{bad}: {e}");
        }
        assert_eq!(millis("250"), Ok(250));
        assert!(millis("0").unwrap_err().to_string().contains("1..=3600000"));
        assert!(millis("18446744073709551615").unwrap_err().to_string().contains("outside"));
        assert!(millis("-5").is_err());
        assert_eq!(positive_minutes("10"), Ok(10.0));
        assert!(positive_minutes("0").is_err() && positive_minutes("inf").is_err() && positive_minutes("1e9").is_err());
        assert_eq!(whole_seconds("60"), Ok(60));
        assert!(whole_seconds("0").is_err() && whole_seconds("2592001").is_err());
        assert_eq!(millis_or_zero("0"), Ok(0));
        assert_eq!(rate("0"), Ok(0.0));
        assert!(rate("-1").is_err() && rate("inf").is_err() && rate("1e6").is_err());
        // regression (issue 61): 1e-300 passed and the player panicked making a Duration of it
        assert_eq!(rate("0.001"), Ok(0.001));
        assert!(rate("1e-300").unwrap_err().to_string().contains("[0.001, 1000]"));
        assert_eq!(steps("0"), Ok(0));
        assert!(positive_steps("0").is_err() && steps("1000001").is_err());
    }
}

/// `--lr-final`: a learning rate to anneal to, or `none` (constant).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LrFinal(pub Option<f64>);

impl std::str::FromStr for LrFinal {
    type Err = BadValue;
    fn from_str(s: &str) -> Result<Self, BadValue> {
        match s.trim() {
            "none" => Ok(LrFinal(None)),
            v => Ok(LrFinal(Some(number(v, "number or `none`")?))),
        }
    }
}

/// `--image FRAME:INPUT`: the rendered frame's side and the network input's, in pixels (the
/// config's validation checks the pair).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageSizes {
    /// Rendered frame side.
    pub frame: usize,
    /// Network input side (the crop).
    pub input: usize,
}

impl std::str::FromStr for ImageSizes {
    type Err = BadValue;
    fn from_str(s: &str) -> Result<Self, BadValue> {
        let bad =
            || BadValue::NotANumber { given: s.to_string(), kind: "pair of sizes FRAME:INPUT, e.g. 76:64".into() };
        let (f, i) = s.split_once(':').ok_or_else(bad)?;
        Ok(ImageSizes { frame: f.trim().parse().map_err(|_| bad())?, input: i.trim().parse().map_err(|_| bad())? })
    }
}

/// The help of a corruption flag, listing the names from the type.
pub fn corruption_help() -> String {
    format!("Symmetry corruptions (docs/paper.md §5): {}", equiarm_types::Corruption::help())
}

/// An env's namespace, `/NAME`: one level (the env's name in messages is NAME), NAME of ASCII letters,
/// digits and `_`, not starting with a digit, as ROS 2 names are. `NAME` and `/NAME/` are taken as
/// `/NAME`. Used by every flag that names an env, so the trainer accepts only what a sim accepts.
pub fn env_namespace(s: &str) -> Result<String, String> {
    let name = s.strip_prefix('/').unwrap_or(s);
    let name = name.strip_suffix('/').unwrap_or(name);
    let ok = name.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    match ok {
        true => Ok(format!("/{name}")),
        false => Err(format!(
            "'{}' is not an env namespace: one level like /env0 (letters, digits and _, not starting with a digit)",
            equiarm_msgs::shown(s)
        )),
    }
}

#[cfg(test)]
mod namespace_tests {
    use super::env_namespace;

    /// Regression (issue 61): the trainer took an `--eval-namespace` the sim refuses, and then waited
    /// for an env that could never exist. Every env flag now parses with the sim's rule.
    #[test]
    fn env_namespaces_are_one_ros_level() {
        for (given, want) in [("/env0", "/env0"), ("eval", "/eval"), ("/eval/", "/eval"), ("/_x1", "/_x1")] {
            assert_eq!(env_namespace(given).as_deref(), Ok(want));
        }
        for bad in ["", "/", "/a/b", "/0env", "/env 0", "/env-0", "//env0", "/é"] {
            let e = env_namespace(bad).unwrap_err();
            assert!(e.contains("not an env namespace"), "{bad}: {e}");
        }
    }
}
