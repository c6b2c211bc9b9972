//! The API described as an OpenAPI document (utoipa), built from the
//! handlers' annotations and the answer types themselves, with the list of
//! stopping rules filled in from the rule registry. `docs/openapi.json` is a
//! committed copy; a test checks it equals what the server serves.

use super::body::ImageUpload;
use super::errors::{ErrorBody, ErrorDetail};
use super::images::{self, Compacted, ImageItem, ImagePage, Written};
use super::localize;
use super::status::{self, MapInfo, OrbPassInfo, PlanCost, PlanInfo, Status};
use super::{page, thumbnails};
use crate::report::{
    Candidate, CandidateMatches, FeatureUse, FilteredCandidate, FullRace, ImageSize, Localization,
    MapIdentity, RacePoint, RaceTrace, RuleReport, SequenceAnswer, Timings,
};
use crate::search::StopInfo;
use crate::search::stop::{
    GENERIC_PARAMETER, OR_VERIFIED, Parameter, RULES, Range, rule_info, rule_names,
};
use std::sync::LazyLock;
use utoipa::OpenApi;
use utoipa::openapi::path::ParameterIn;
use utoipa::openapi::schema::{ObjectBuilder, Type};

#[derive(OpenApi)]
#[openapi(
    info(
        title = "bowloc",
        description = "Recognises a place from a picture: bag-of-words image search over a map of \
                       images, with early-stopping rules that use only as many of the query's \
                       features as needed."
    ),
    paths(
        localize::localize,
        localize::delete_sequence,
        status::healthz,
        status::readyz,
        status::map,
        status::metrics,
        status::openapi,
        thumbnails::thumbnail,
        page::index,
        page::script,
        page::style,
        images::list_images,
        images::get_image,
        images::put_image,
        images::delete_image,
        images::compact,
    ),
    components(schemas(
        Localization, Candidate, FeatureUse, RuleReport, StopInfo, ImageSize, Timings,
        MapIdentity, ErrorBody, ErrorDetail, Status, MapInfo, PlanInfo, PlanCost, OrbPassInfo, ImageUpload, Binary, RaceTrace,
        RacePoint, FullRace, CandidateMatches, SequenceAnswer, FilteredCandidate,
        ImageItem, ImagePage, Written, Compacted, crate::live::Compaction,
        crate::live::ChangesInfo,
    )),
    modifiers(&BearerAuth),
    tags(
        (name = "localize", description = "Localize a query image against the loaded map."),
        (name = "operations", description = "Health, readiness, metrics and descriptions."),
        (name = "page", description = "The page for people at `/` and the map image thumbnails it shows."),
        (name = "images", description = "The map's images: add, replace, remove, list; compaction. Writes need the bearer token."),
    )
)]
struct ApiDoc;

/// The write endpoints' bearer token (`[auth] write_token`).
struct BearerAuth;

impl utoipa::Modify for BearerAuth {
    fn modify(&self, doc: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{Http, HttpAuthScheme, SecurityScheme};
        doc.components
            .get_or_insert_with(Default::default)
            .add_security_scheme(
                "bearer",
                SecurityScheme::Http(Http::new(HttpAuthScheme::Bearer)),
            );
    }
}

/// Raw bytes in a request or answer body (an image, a protobuf message):
/// `type: string, format: binary`.
#[derive(utoipa::ToSchema)]
#[schema(value_type = String, format = Binary)]
#[allow(dead_code)]
pub struct Binary(Vec<u8>);

/// The document.
pub fn document() -> utoipa::openapi::OpenApi {
    let mut doc = ApiDoc::openapi();
    describe_rules(&mut doc);
    doc
}

/// The document as served and committed: pretty JSON and a final newline.
pub fn json() -> &'static str {
    static JSON: LazyLock<String> = LazyLock::new(|| {
        let mut s = document()
            .to_pretty_json()
            .expect("the document serializes");
        s.push('\n');
        s
    });
    &JSON
}

/// The `rule` parameter of `/localize` lists the registry's rules.
fn describe_rules(doc: &mut utoipa::openapi::OpenApi) {
    let Some(op) = doc
        .paths
        .paths
        .get_mut("/localize")
        .and_then(|item| item.post.as_mut())
    else {
        return;
    };
    let rules: Vec<String> = RULES
        .iter()
        .map(|r| match &r.parameter {
            Some(p) => format!(
                "`{}` ({}: {}, {}): {}",
                r.name,
                p.name,
                p.meaning,
                p.range.describe(),
                r.about
            ),
            None => format!("`{}`: {}", r.name, r.about),
        })
        .collect();
    for p in op.parameters.iter_mut().flatten() {
        let utoipa::openapi::RefOr::T(p) = p else {
            continue;
        };
        if p.name == "rule" && p.parameter_in == ParameterIn::Query {
            p.description = Some(format!(
                "Stopping rule (default from the configuration). Without a parameter it takes \
                 the configured one if it is the configured rule.\n\n- {}",
                rules.join("\n- ")
            ));
            p.schema = Some(
                ObjectBuilder::new()
                    .schema_type(Type::String)
                    .enum_values(Some(rule_names()))
                    .into(),
            );
        } else if p.name == OR_VERIFIED && p.parameter_in == ParameterIn::Query {
            // the verified rule's own parameter, so its range
            let verified = rule_info("verified").and_then(|r| r.parameter);
            if let Some(q) = verified {
                set_range(p, q.range);
            }
        } else if p.parameter_in == ParameterIn::Query {
            describe_rule_parameter(p);
        }
    }
}

/// A rule parameter of `/localize` (the generic one, or one a registry rule
/// names its parameter): what it means for each rule that takes it, and,
/// where those rules agree, its range.
fn describe_rule_parameter(p: &mut utoipa::openapi::path::Parameter) {
    let takers: Vec<(&str, Parameter)> = RULES
        .iter()
        .filter_map(|r| r.parameter.map(|q| (r.name, q)))
        .filter(|(_, q)| q.name == p.name)
        .collect();
    if takers.is_empty() {
        return;
    }
    let uses: Vec<String> = takers
        .iter()
        .map(|(rule, q)| format!("`{rule}`: {}; {}", q.meaning, q.range.describe()))
        .collect();
    let head = if p.name == GENERIC_PARAMETER {
        "The parameter of any rule that takes one (its generic name); the own name of the \
         parameter of"
    } else {
        "The parameter of"
    };
    p.description = Some(format!("{head}\n\n- {}", uses.join("\n- ")));
    let range = takers[0].1.range;
    if p.name == GENERIC_PARAMETER || takers.iter().any(|(_, q)| q.range != range) {
        return;
    }
    set_range(p, range);
}

/// `p`'s minimum and maximum, as `range` has them.
fn set_range(p: &mut utoipa::openapi::path::Parameter, range: Range) {
    use utoipa::openapi::{RefOr, Schema};
    let Some(RefOr::T(Schema::Object(o))) = p.schema.as_mut() else {
        return;
    };
    let number = |v: f64| {
        if v.fract() == 0.0 {
            utoipa::Number::Int(v as isize)
        } else {
            utoipa::Number::Float(v)
        }
    };
    let (lo, lo_out, hi, hi_out) = range.bounds();
    if lo_out {
        o.exclusive_minimum = Some(number(lo));
    } else {
        o.minimum = Some(number(lo));
    }
    if let Some(hi) = hi {
        if hi_out {
            o.exclusive_maximum = Some(number(hi));
        } else {
            o.maximum = Some(number(hi));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binary_bodies_are_binary_strings_and_ranks_start_at_1() {
        let v: serde_json::Value = serde_json::from_str(json()).unwrap();
        let binary = &v["components"]["schemas"]["Binary"];
        assert_eq!(binary["type"], "string");
        assert_eq!(binary["format"], "binary");
        let op = &v["paths"]["/localize"]["post"];
        let bodies = op["requestBody"]["content"].as_object().unwrap();
        for (media, content) in bodies {
            if media != "multipart/form-data" {
                assert_eq!(
                    content["schema"]["$ref"], "#/components/schemas/Binary",
                    "{media}"
                );
            }
        }
        let protobuf = &op["responses"]["200"]["content"]["application/x-protobuf"];
        assert_eq!(protobuf["schema"]["$ref"], "#/components/schemas/Binary");
        let rank = &v["components"]["schemas"]["Candidate"]["properties"]["rank"];
        assert_eq!(rank["minimum"], 1);
    }

    #[test]
    fn rule_parameter_lists_every_rule() {
        let v: serde_json::Value = serde_json::from_str(json()).unwrap();
        let params = v["paths"]["/localize"]["post"]["parameters"]
            .as_array()
            .unwrap();
        let rule = params.iter().find(|p| p["name"] == "rule").unwrap();
        let listed: Vec<&str> = rule["schema"]["enum"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect();
        assert_eq!(listed, rule_names());
        let rule_parameters = RULES.iter().filter_map(|r| r.parameter.map(|p| p.name));
        for name in ["top_n", GENERIC_PARAMETER, "seed", "min_score"]
            .into_iter()
            .chain(rule_parameters)
        {
            assert!(
                params.iter().any(|p| p["name"] == name),
                "{name} undocumented"
            );
        }
    }

    #[test]
    fn or_verified_takes_the_verified_rules_range() {
        let p = parameter("/localize", "post", OR_VERIFIED);
        let m = rule_info("verified").unwrap().parameter.unwrap();
        let (lo, _, hi, _) = m.range.bounds();
        assert_eq!(p["schema"]["minimum"], lo as u64);
        assert_eq!(p["schema"]["maximum"], hi.unwrap() as u64);
    }

    #[test]
    fn tile_orders_are_named_where_clients_read_them() {
        let described = parameter("/localize", "post", "tile_order");
        let described = described["description"].as_str().unwrap();
        let proto = include_str!("../../proto/localize.proto");
        let proto_comment = proto
            .lines()
            .find(|l| l.contains("The order the tiles were extracted in"))
            .expect("the proto documents the tile order");
        for order in crate::search::TileOrder::ALL {
            let name = format!("`{}`", order.name());
            assert!(described.contains(&name), "OpenAPI: {name} missing");
            assert!(proto_comment.contains(&name), "protobuf: {name} missing");
        }
    }

    /// A parameter of an operation in the served document.
    fn parameter(path: &str, method: &str, name: &str) -> serde_json::Value {
        let v: serde_json::Value = serde_json::from_str(json()).unwrap();
        v["paths"][path][method]["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap_or_else(|| panic!("{method} {path}: no parameter {name}"))
            .clone()
    }

    // utoipa 6 takes only literals for `maximum`, `minimum` and `max_length`;
    // these hold the documented limits to the constants the handlers check.
    #[test]
    fn documented_limits_are_the_handlers_limits() {
        use super::super::images::{DEFAULT_PAGE, MAX_PAGE, MAX_PLACE_LEN, id_rule};
        use super::super::thumbnails::{DEFAULT_SIZE, MAX_SIZE, MIN_SIZE};

        let place = parameter("/images/{id}", "put", "place");
        assert_eq!(place["schema"]["maxLength"], MAX_PLACE_LEN);
        let said = place["description"].as_str().unwrap();
        assert!(
            said.contains(&format!("at most {MAX_PLACE_LEN} bytes")),
            "{said}"
        );

        let id = parameter("/images/{id}", "put", "id");
        assert!(id["description"].as_str().unwrap().contains(&id_rule()));

        let limit = parameter("/images", "get", "limit");
        assert_eq!(limit["schema"]["minimum"], 1);
        assert_eq!(limit["schema"]["maximum"], MAX_PAGE);
        let said = limit["description"].as_str().unwrap();
        let range = format!("1 to {MAX_PAGE} (default {DEFAULT_PAGE})");
        assert!(said.contains(&range), "{said}");

        let size = parameter("/images/{id}/thumbnail", "get", "size");
        assert_eq!(size["schema"]["minimum"], MIN_SIZE);
        assert_eq!(size["schema"]["maximum"], MAX_SIZE);
        let said = size["description"].as_str().unwrap();
        let range = format!("{MIN_SIZE} to {MAX_SIZE} (default {DEFAULT_SIZE})");
        assert!(said.contains(&range), "{said}");
    }
}
