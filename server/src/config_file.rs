//! The server's configuration in layers: built-in defaults, then a TOML
//! file (`--config` or `MESHLESS_CONFIG`), then environment variables,
//! then command-line flags. The file's keys are the flags' names
//! (`grpc-addr = "0.0.0.0:50051"`); its values become the flags'
//! defaults, so clap's own order (flag, then environment, then default)
//! gives the layering, and every value is parsed and checked by the same
//! code whichever layer it came from. `--print-config` shows the result,
//! each value with the layer it came from, as a file the server reads.

use clap::parser::ValueSource;
use clap::{ArgMatches, Command};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// Longest config file read, bytes.
const MAX_FILE_BYTES: u64 = 1 << 20;

/// Arguments that are not settings, so a file may not set them.
const NOT_SETTINGS: &[&str] = &["config", "print_config", "help", "version"];

/// The config file named by `--config FILE` (or `--config=FILE`) in
/// `args`, else by `MESHLESS_CONFIG`.
pub fn config_path(args: &[OsString]) -> Option<PathBuf> {
    let mut args = args.iter();
    while let Some(arg) = args.next() {
        let text = arg.to_string_lossy();
        if text == "--config" {
            return args.next().map(PathBuf::from);
        }
        if let Some(path) = text.strip_prefix("--config=") {
            return Some(PathBuf::from(path));
        }
    }
    std::env::var_os("MESHLESS_CONFIG").map(PathBuf::from)
}

/// `command` with the settings of the TOML file at `path` as its
/// defaults, and the ids of the settings the file set.
///
/// # Errors
/// An unreadable file, TOML that does not parse, a key that is no
/// setting (the message lists them) or a value that is not a string,
/// number, boolean or array of them.
pub fn with_file(mut command: Command, path: &Path) -> Result<(Command, Vec<String>), String> {
    let shown = path.display();
    // A regular file only: a FIFO or a device named by mistake fails the
    // start at once instead of hanging it or filling memory.
    let text = crate::files::read_regular_text(path, MAX_FILE_BYTES)
        .map_err(|e| format!("cannot read config file {shown}: {e}"))?;
    let table: toml::Table =
        toml::from_str(&text).map_err(|e| format!("config file {shown}: {e}"))?;
    let mut set = Vec::new();
    for (key, value) in table {
        let id = settings(&command)
            .find(|(_, long)| *long == key)
            .map(|(id, _)| id)
            .ok_or_else(|| {
                let keys: Vec<String> = settings(&command).map(|(_, l)| l).collect();
                format!(
                    "config file {shown}: {:?} is not a setting; the settings are {}",
                    key.chars().take(64).collect::<String>(),
                    keys.join(", ")
                )
            })?;
        let text = value_text(&value).ok_or_else(|| {
            format!("config file {shown}: {key} must be a string, number, boolean or array")
        })?;
        command = command.mut_arg(&id, |arg| arg.default_value(text));
        set.push(id);
    }
    Ok((command, set))
}

/// `(id, long name)` of every setting of `command`.
fn settings(command: &Command) -> impl Iterator<Item = (String, String)> + '_ {
    command.get_arguments().filter_map(|arg| {
        let id = arg.get_id().as_str();
        let long = arg.get_long()?;
        (!NOT_SETTINGS.contains(&id)).then(|| (id.to_owned(), long.to_owned()))
    })
}

/// A TOML value as a flag's text: arrays comma-separated, as the
/// list-valued flags take them.
fn value_text(value: &toml::Value) -> Option<String> {
    match value {
        toml::Value::String(s) => Some(s.clone()),
        toml::Value::Integer(i) => Some(i.to_string()),
        toml::Value::Float(f) => Some(f.to_string()),
        toml::Value::Boolean(b) => Some(b.to_string()),
        toml::Value::Array(items) => items
            .iter()
            .map(value_text)
            .collect::<Option<Vec<_>>>()
            .map(|parts| parts.join(",")),
        toml::Value::Datetime(_) | toml::Value::Table(_) => None,
    }
}

/// The resolved settings as a TOML config file, by name, each with the
/// layer it came from; unset optional settings as comments.
pub fn render(command: &Command, matches: &ArgMatches, file: Option<(&Path, &[String])>) -> String {
    let mut out =
        String::from("# meshless-server configuration: flag > environment > file > default\n");
    let from_file: &[String] = match file {
        Some((path, set)) => {
            out.push_str(&format!("# file: {}\n", path.display()));
            set
        }
        None => &[],
    };
    // By name: the file's settings would otherwise come last.
    let mut all: Vec<(String, String)> = settings(command).collect();
    all.sort_by(|a, b| a.1.cmp(&b.1));
    for (id, long) in all {
        let values: Option<Vec<String>> = matches
            .get_raw(&id)
            .map(|values| values.map(|v| v.to_string_lossy().into_owned()).collect());
        let source = match matches.value_source(&id) {
            Some(ValueSource::CommandLine) => "flag",
            Some(ValueSource::EnvVariable) => "environment",
            Some(ValueSource::DefaultValue) if from_file.contains(&id) => "file",
            Some(ValueSource::DefaultValue) => "default",
            _ => "unset",
        };
        match values {
            Some(values) if command_is_list(command, &id) => {
                let items: Vec<String> = values.iter().map(|v| toml_value(v)).collect();
                out.push_str(&format!("{long} = [{}]  # {source}\n", items.join(", ")));
            }
            Some(values) => {
                let value = values.first().map(|v| toml_value(v)).unwrap_or_default();
                out.push_str(&format!("{long} = {value}  # {source}\n"));
            }
            None => out.push_str(&format!("# {long} =  # unset\n")),
        }
    }
    out
}

/// Whether the setting takes a list.
fn command_is_list(command: &Command, id: &str) -> bool {
    command
        .get_arguments()
        .find(|a| a.get_id() == id)
        .is_some_and(|a| a.get_value_delimiter().is_some())
}

/// `text` as a TOML value: a number or boolean as it is, anything else
/// quoted.
fn toml_value(text: &str) -> String {
    let plain = text.parse::<i64>().is_ok()
        || (text.parse::<f64>().is_ok_and(f64::is_finite) && !text.contains(char::is_alphabetic))
        || text == "true"
        || text == "false";
    if plain {
        text.to_owned()
    } else {
        toml::Value::String(text.to_owned()).to_string()
    }
}
