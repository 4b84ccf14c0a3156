//! `visage eval --composite`: a composite built in-process from trained
//! sources against its ground truth (see `train::composite_eval`), printed
//! as tables or one JSON document, with an optional picture.

use super::train::EvalArgs;
use crate::compose::recipe::Fit;
use crate::error::{Error, Result};
use crate::pipeline::DatabaseSpec;
use crate::train::composite_eval::{evaluate_composite, CompositeReport, EvalOptions, Quality};
use crate::train::dataset::Dataset;
use crate::train::seam_fit::SeamFit;

/// Runs `visage eval --composite --db TRAINED RECIPE DATASET`.
pub fn run(args: &EvalArgs) -> Result<()> {
    let trained_dir = args
        .db
        .as_ref()
        .expect("clap requires --db with --composite");
    let recipe = crate::compose::recipe::Recipe::load(args.recipe())?;
    let dataset = Dataset::load(args.dataset())?;
    let spec = DatabaseSpec {
        db: trained_dir.display().to_string(),
        ..DatabaseSpec::default()
    };
    let (trained, _) = spec.load()?;
    for name in recipe.source_names() {
        if !trained.sources.iter().any(|s| s.name == name) {
            return Err(Error::input(format!(
                "{} has no trained source '{}', which the recipe needs: train it into that folder first",
                trained_dir.display(),
                crate::text::printable(&name)
            )));
        }
    }
    let options = EvalOptions {
        border_px: args.border_px,
        picture_views: if args.picture.is_some() { 3 } else { 0 },
        arrays: args.arrays.clone(),
        fit: match args.seam_fit {
            Some(0) => None,
            Some(steps) => Some(steps),
            None => (recipe.post.fit == Fit::Seams).then_some(SeamFit::default().iterations),
        }
        .map(|iterations| SeamFit {
            iterations,
            size: args.seam_fit_size.unwrap_or(SeamFit::default().size),
            renderer: args
                .seam_fit_renderer
                .unwrap_or(SeamFit::default().renderer),
            ..SeamFit::default()
        }),
    };
    if options.fit.is_none() {
        if args.seam_fit_size.is_some() {
            return Err(super::compose::without_fit("--seam-fit-size"));
        }
        if args.seam_fit_renderer.is_some() {
            return Err(super::compose::without_fit("--seam-fit-renderer"));
        }
    }
    if let Some(dir) = &options.arrays {
        // Before the composites and the fit, which take a while.
        crate::train::composite_eval::arrays::prepare(dir)?;
    }
    let (report, pictures) = evaluate_composite(&trained, &recipe, &dataset, &options)?;
    if let Some(path) = &args.picture {
        let mut images = Vec::new();
        let mut rows = Vec::new();
        for (label, views) in pictures {
            // Small images are enlarged so the column titles fit over them.
            let factor = 96u32.div_ceil(views[0].width.max(1)).max(1);
            images.extend(views.map(|v| v.resized(v.width * factor, v.height * factor)));
            rows.push(label);
        }
        crate::study::plot::labelled_grid(&images, &["truth", "composite", "dE 0-20"], &rows)?
            .save_png(path)?;
    }
    if args.json() {
        println!(
            "{}",
            serde_json::to_string(&report).expect("reports serialise")
        );
    } else {
        print_report(&report);
    }
    Ok(())
}

fn row(name: &str, q: &Quality) -> String {
    if q.pixels == 0 {
        return format!("  {name:<16}       -     (no pixels)");
    }
    format!(
        "  {name:<16} {:>7.2} dB  SSIM {:.4}  ΔE {:>5.2}  ({} px)",
        q.psnr_db, q.ssim, q.delta_e, q.pixels
    )
}

/// Regions listed under "error over the ceiling by region".
const REGIONS_SHOWN: usize = 6;

/// Per region listed, how many of the regions beside its band are named
/// (the costliest first).
const BESIDE_SHOWN: usize = 3;

/// A PSNR for a table cell, "-" where it is not a number (no pixels).
fn decibels(db: f64) -> String {
    if db.is_finite() {
        format!("{db:5.2}")
    } else {
        format!("{:>5}", "-")
    }
}

fn print_report(r: &CompositeReport) {
    println!(
        "composite against its ground truth: {} views, band {} px",
        r.views, r.border_px
    );
    println!("{}", row("head", &r.quality));
    // Each split beside the ceiling on the same views: on "train" the
    // sources are scored on images they were fitted to.
    let with_ceiling = |name: &str, q: &Quality, ceiling: Option<&Quality>| match ceiling {
        Some(c) if c.pixels > 0 && q.pixels > 0 => {
            format!("{}  ceiling {:.2} dB", row(name, q), c.psnr_db)
        }
        _ => row(name, q),
    };
    for (split, q) in &r.splits {
        println!("{}", with_ceiling(split, q, r.ceiling_splits.get(split)));
    }
    println!(
        "{}",
        with_ceiling("held out", &r.held_out, Some(&r.ceiling_held_out))
    );
    println!("{}", row("ceiling", &r.ceiling));
    println!("{}", row("border band", &r.border));
    println!("{}", row("interior", &r.interior));
    println!("{}", row("skin", &r.skin));
    println!("{}", row("non-skin", &r.non_skin));
    println!("{}", row("ceiling skin", &r.ceiling_skin));
    println!("{}", row("ceiling non-skin", &r.ceiling_non_skin));
    println!("{}", row("ceiling band", &r.ceiling_border));
    println!("{}", row("ceiling interior", &r.ceiling_interior));
    println!(
        "  leak             {:.2} % of colour from another source ({:.2} % of {} interior px over 5 %)",
        100.0 * r.leak.mean,
        100.0 * r.leak.over_5_percent,
        r.leak.pixels
    );
    println!(
        "  holes            {:.2} % of head px covered less than half",
        100.0 * r.holes
    );
    println!("{}", row("open mouth", &r.open_mouth));
    println!("{}", row("closed mouth", &r.closed_mouth));
    println!("groups (source; PSNR against the ceiling of that source on itself):");
    for g in &r.groups {
        println!(
            "{}  ceiling {:.2} dB",
            row(&format!("{} ({})", g.group, g.source), &g.quality),
            g.ceiling_psnr_db
        );
    }
    let head_error = 10f64.powf(-r.quality.psnr_db / 10.0) * r.quality.pixels as f64;
    println!("error over the ceiling by region (dB: composite/source's own; % of head error):");
    for g in r
        .regions
        .iter()
        .filter(|g| g.excess > 0.0)
        .take(REGIONS_SHOWN)
    {
        println!(
            "  {:<23} band {}/{}  interior {}/{}  {:>4.1} %",
            format!("{} ({})", g.region, g.source),
            decibels(g.band.psnr_db),
            decibels(g.ceiling_band_psnr_db),
            decibels(g.interior.psnr_db),
            decibels(g.ceiling_interior_psnr_db),
            100.0 * g.excess / head_error
        );
        let seams: Vec<String> = g
            .beside
            .iter()
            .filter(|b| b.excess > 0.0)
            .take(BESIDE_SHOWN)
            .map(|b| {
                format!(
                    "{} {} dB {:.1} %",
                    b.region,
                    decibels(b.quality.psnr_db).trim_start(),
                    100.0 * b.excess / head_error
                )
            })
            .collect();
        if !seams.is_empty() {
            println!("    band beside {}", seams.join(", "));
        }
    }
    println!("sources on their own ground truth:");
    for s in &r.sources {
        println!("{}", row(&s.source, &s.quality));
    }
    println!("decomposition (head / border / interior PSNR, skin / non-skin ΔE):");
    for s in &r.decomposition {
        println!(
            "  {:<12} {:>6.2} {:>6.2} {:>6.2} dB   ΔE {:>5.2} {:>5.2}",
            s.step,
            s.quality.psnr_db,
            s.border.psnr_db,
            s.interior.psnr_db,
            s.skin.delta_e,
            s.non_skin.delta_e
        );
    }
    if let Some(fit) = &r.seam_fit {
        println!(
            "seam fit: {} Gaussians in {:.1} s on the {}",
            fit.fitted,
            fit.ms / 1e3,
            if fit.on_gpu { "GPU" } else { "CPU" }
        );
    }
    println!("evaluated in {:.1} s", r.eval_ms / 1e3);
}
