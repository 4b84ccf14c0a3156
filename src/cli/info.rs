//! `visage info`: what is in the database, as text or JSON, and OBJ export of the
//! sources' neutral meshes.

use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use super::DbArgs;
use crate::avatar::database::Database;
use crate::error::{Error, Result};
use crate::io::obj::write_obj;
use crate::model::head::JOINT_NAMES;
use crate::model::regions::{Group, Region};
use crate::model::topology::connected_components;
use crate::text::printable;

/// Arguments of `visage info`.
#[derive(Args, Debug, Clone, Default)]
pub struct InfoArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Print one JSON document instead of text.
    #[arg(long)]
    json: bool,
    /// Also write each source's neutral mesh (static offset included) as an OBJ
    /// with per-region vertex colours into this folder.
    #[arg(long, value_name = "DIR")]
    export_obj: Option<PathBuf>,
}

/// Runs `visage info`.
pub fn run(args: &InfoArgs) -> Result<()> {
    let (db, elapsed) = args.db.load()?;
    if let Some(dir) = &args.export_obj {
        export_objs(&db, dir)?;
    }
    let report = report(&db, args, elapsed.as_secs_f64() * 1e3);
    if args.json {
        println!("{report}");
    } else {
        print_text(&report);
    }
    Ok(())
}

fn export_objs(db: &Database, dir: &PathBuf) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io("create", dir, e))?;
    for source in &db.sources {
        let file: String = source
            .name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let path = dir.join(format!("{file}.obj"));
        let neutral = source.neutral(&db.model);
        write_obj(
            &path,
            &neutral,
            &db.model.triangles,
            &db.model.triangle_regions,
        )?;
    }
    Ok(())
}

/// The info document (also the source of the text output).
fn report(db: &Database, args: &InfoArgs, generation_ms: f64) -> serde_json::Value {
    let model = &db.model;
    let mut per_region = [0usize; Region::COUNT];
    for r in &model.triangle_regions {
        per_region[r.index()] += 1;
    }
    let (parts, labels) = connected_components(model.vertex_count(), &model.triangles);
    let regions: Vec<_> = Region::ALL
        .iter()
        .map(|r| {
            json!({
                "name": r.name(),
                "group": r.group().name(),
                "triangles": per_region[r.index()],
                "anchors": r.anchor_regions().map(|a| a.map(|x| x.name())),
            })
        })
        .collect();
    let groups: Vec<_> = Group::ALL
        .iter()
        .map(|g| json!({"name": g.name(), "regions": g.regions().map(Region::name).collect::<Vec<_>>()}))
        .collect();
    let mut part_sizes = vec![0usize; parts];
    for l in &labels {
        part_sizes[*l as usize] += 1;
    }
    let sources: Vec<_> = db
        .sources
        .iter()
        .map(|s| {
            json!({
                "name": printable(&s.name),
                "gaussians": s.gaussians.len(),
                "sh_degree": s.gaussians.sh_degree,
                "motion": printable(&s.motion.name),
                "motion_frames": s.motion.frames(),
            })
        })
        .collect();
    let motions: Vec<_> = db
        .motions
        .iter()
        .map(|m| json!({"name": printable(&m.name), "frames": m.frames(), "fps": m.fps}))
        .collect();
    json!({
        "database": printable(&db.label),
        "seed": (args.db.db == "builtin").then_some(args.db.seed),
        "generation_ms": (generation_ms * 10.0).round() / 10.0,
        "model": {
            "vertices": model.vertex_count(),
            "triangles": model.triangle_count(),
            "components": parts,
            "component_vertices": part_sizes,
            "shape_components": model.shape_basis.names(),
            "expression_components": model.expression_basis.names(),
            "joints": JOINT_NAMES,
            "pose_correctives": model.pose_correctives.is_some(),
            "mouth_cavity": model.mouth_cavity.as_ref().map(|c| json!({
                "vertices": model.vertex_count() - c.first_vertex,
                "triangles": model.triangle_count() - c.first_triangle,
            })),
            "regions": regions,
            "groups": groups,
        },
        "sources": sources,
        "total_gaussians": db.total_gaussians(),
        "motions": motions,
    })
}

fn print_text(r: &serde_json::Value) {
    let m = &r["model"];
    let database = r["database"].as_str().unwrap_or("");
    let ms = r["generation_ms"].as_f64().unwrap_or(0.0);
    match r["seed"].as_u64() {
        Some(seed) => println!("database {database} (seed {seed}), generated in {ms:.0} ms"),
        None => println!("database {database}, loaded in {ms:.0} ms"),
    }
    println!(
        "model: {} vertices, {} triangles, {} connected parts, {} shape and {} expression components, joints {}",
        m["vertices"],
        m["triangles"],
        m["components"],
        m["shape_components"].as_array().map_or(0, Vec::len),
        m["expression_components"].as_array().map_or(0, Vec::len),
        JOINT_NAMES.join(", ")
    );
    if let Some(c) = m["mouth_cavity"].as_object() {
        println!(
            "mouth cavity added behind the lips: {} vertices, {} triangles (files never see them)",
            c["vertices"], c["triangles"]
        );
    }
    println!("regions (18 in 7 groups):");
    for g in m["groups"].as_array().into_iter().flatten() {
        let names: Vec<String> = g["regions"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|name| {
                let tris = m["regions"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .find(|x| x["name"] == *name)
                    .map_or(0, |x| x["triangles"].as_u64().unwrap_or(0));
                format!("{} {}", name.as_str().unwrap_or(""), tris)
            })
            .collect();
        println!(
            "  {:<6} {}",
            g["name"].as_str().unwrap_or(""),
            names.join(", ")
        );
    }
    println!(
        "sources ({}), {} Gaussians in all:",
        r["sources"].as_array().map_or(0, Vec::len),
        r["total_gaussians"]
    );
    for s in r["sources"].as_array().into_iter().flatten() {
        println!(
            "  {:<8} {:>7} Gaussians, SH degree {}, motion {}",
            s["name"].as_str().unwrap_or(""),
            s["gaussians"],
            s["sh_degree"],
            s["motion"].as_str().unwrap_or("")
        );
    }
    println!("motions:");
    for mo in r["motions"].as_array().into_iter().flatten() {
        println!(
            "  {:<10} {} frames at {} fps",
            mo["name"].as_str().unwrap_or(""),
            mo["frames"],
            mo["fps"]
        );
    }
}
