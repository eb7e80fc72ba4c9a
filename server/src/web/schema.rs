//! The service's schema as the page's codec reads it (`GET
//! /schema.json`), made from the very descriptors the server's code was
//! generated from: the page encodes and decodes every message without a
//! protobuf toolchain, and cannot drift from the `.proto` files.
//!
//! `{"messages": {NAME: {"fields": [{name, number, type, ref, repeated,
//! optional, oneof}]}}, "enums": {NAME: {VALUE: NUMBER}}, "methods":
//! {METHOD: {input, output, stream}}}`, names fully qualified without the
//! leading dot, `type` the scalar's name or `message` or `enum`.

use anyhow::{Context, Result, bail};
use prost::Message;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, FileDescriptorSet};
use serde_json::{Map, Value, json};

/// The service the page calls.
const SERVICE: &str = "Simulation";

/// The schema of `meshless.v1`, from an encoded `FileDescriptorSet`.
///
/// # Errors
/// Descriptors that do not decode, or a field of a kind the page's codec
/// does not read (groups).
pub fn json(descriptor_set: &[u8]) -> Result<String> {
    let set = FileDescriptorSet::decode(descriptor_set).context("the file descriptor set")?;
    let mut messages = Map::new();
    let mut enums = Map::new();
    let mut methods = Map::new();
    for file in &set.file {
        let package = file.package();
        for message in &file.message_type {
            add_message(package, message, &mut messages, &mut enums)?;
        }
        for en in &file.enum_type {
            enums.insert(format!("{package}.{}", en.name()), enum_values(en));
        }
        for service in file.service.iter().filter(|s| s.name() == SERVICE) {
            for method in &service.method {
                methods.insert(
                    method.name().to_owned(),
                    json!({
                        "input": unqualified(method.input_type()),
                        "output": unqualified(method.output_type()),
                        "stream": method.server_streaming(),
                    }),
                );
            }
        }
    }
    if methods.is_empty() {
        bail!("the descriptors hold no service {SERVICE}");
    }
    Ok(json!({ "messages": messages, "enums": enums, "methods": methods }).to_string())
}

fn add_message(
    scope: &str,
    message: &DescriptorProto,
    messages: &mut Map<String, Value>,
    enums: &mut Map<String, Value>,
) -> Result<()> {
    let name = format!("{scope}.{}", message.name());
    for nested in &message.nested_type {
        add_message(&name, nested, messages, enums)?;
    }
    for en in &message.enum_type {
        enums.insert(format!("{name}.{}", en.name()), enum_values(en));
    }
    let mut fields = Vec::new();
    for field in &message.field {
        let (kind, reference) = match field.r#type() {
            Type::Message => ("message", Some(unqualified(field.type_name()))),
            Type::Enum => ("enum", Some(unqualified(field.type_name()))),
            Type::Group => bail!(
                "{name}.{} is a group, which the page cannot read",
                field.name()
            ),
            scalar => (scalar_name(scalar), None),
        };
        let optional = field.proto3_optional();
        fields.push(json!({
            "name": field.name(),
            "number": field.number(),
            "type": kind,
            "ref": reference,
            "repeated": field.label() == Label::Repeated,
            "optional": optional,
            // A member of a real oneof (not proto3's synthetic one for
            // `optional`): absent unless set.
            "oneof": field.oneof_index.is_some() && !optional,
        }));
    }
    messages.insert(name, json!({ "fields": fields }));
    Ok(())
}

fn enum_values(en: &prost_types::EnumDescriptorProto) -> Value {
    Value::Object(
        en.value
            .iter()
            .map(|v| (v.name().to_owned(), json!(v.number())))
            .collect(),
    )
}

fn unqualified(name: &str) -> &str {
    name.strip_prefix('.').unwrap_or(name)
}

fn scalar_name(kind: Type) -> &'static str {
    match kind {
        Type::Double => "double",
        Type::Float => "float",
        Type::Int64 => "int64",
        Type::Uint64 => "uint64",
        Type::Int32 => "int32",
        Type::Fixed64 => "fixed64",
        Type::Fixed32 => "fixed32",
        Type::Bool => "bool",
        Type::String => "string",
        Type::Bytes => "bytes",
        Type::Uint32 => "uint32",
        Type::Sfixed32 => "sfixed32",
        Type::Sfixed64 => "sfixed64",
        Type::Sint32 => "sint32",
        Type::Sint64 => "sint64",
        Type::Message | Type::Enum | Type::Group => "message",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schema() -> Value {
        serde_json::from_str(&json(meshless_proto::FILE_DESCRIPTOR_SET).expect("schema"))
            .expect("JSON")
    }

    fn field<'a>(schema: &'a Value, message: &str, name: &str) -> &'a Value {
        schema["messages"][message]["fields"]
            .as_array()
            .expect("fields")
            .iter()
            .find(|f| f["name"] == name)
            .unwrap_or_else(|| panic!("{message}.{name}"))
    }

    #[test]
    fn the_schema_describes_frames_as_the_generated_code_does() {
        let schema = schema();
        let header = field(&schema, "meshless.v1.Frame", "header");
        assert_eq!(header["number"], 1);
        assert_eq!(header["type"], "message");
        assert_eq!(header["ref"], "meshless.v1.FrameHeader");
        assert_eq!(header["repeated"], false);
        let fields = field(&schema, "meshless.v1.Frame", "fields");
        assert_eq!(fields["repeated"], true);
        let data = field(&schema, "meshless.v1.FieldData", "data");
        assert_eq!(
            (data["number"].as_i64(), data["type"].as_str()),
            (Some(4), Some("bytes"))
        );
        let step = field(&schema, "meshless.v1.FrameHeader", "step");
        assert_eq!(step["type"], "uint64");
        assert_eq!(schema["enums"]["meshless.v1.FieldKind"]["FIELD_KIND_ID"], 9);
    }

    #[test]
    fn oneofs_and_optionals_are_told_apart() {
        let schema = schema();
        let forever = field(&schema, "meshless.v1.RunRequest", "forever");
        assert_eq!(
            (forever["oneof"].as_bool(), forever["optional"].as_bool()),
            (Some(true), Some(false))
        );
        let factor = field(&schema, "meshless.v1.RunRequest", "realtime_factor");
        assert_eq!(
            (factor["oneof"].as_bool(), factor["optional"].as_bool()),
            (Some(false), Some(true))
        );
    }

    #[test]
    fn every_method_of_the_service_is_there() {
        let schema = schema();
        let methods = schema["methods"].as_object().expect("methods");
        let next = &methods["NextFrame"];
        assert_eq!(next["input"], "meshless.v1.NextFrameRequest");
        assert_eq!(next["stream"], false);
        assert_eq!(methods["WatchStatus"]["stream"], true);
        // As many as the service's `rpc` lines.
        let rpcs = include_str!("../../../proto/meshless/v1/simulation.proto")
            .lines()
            .filter(|l| l.trim().starts_with("rpc "))
            .count();
        assert_eq!(methods.len(), rpcs);
    }
}
