//! The built-in synthetic database: deterministic, valid, and the sizes promised.

use visage::avatar::binding::triangle_frames;
use visage::avatar::database::Database;
use visage::avatar::synthetic::{builtin_database, SyntheticOptions};
use visage::model::builtin::build_head;

fn db(seed: u64, per_avatar: usize, sources: usize) -> Database {
    builtin_database(
        build_head(),
        SyntheticOptions {
            seed,
            sources,
            gaussians_per_avatar: per_avatar,
        },
    )
    .unwrap()
}

/// Every byte of every source, for comparing whole databases.
fn fingerprint(db: &Database) -> blake3::Hash {
    let mut h = blake3::Hasher::new();
    for s in &db.sources {
        h.update(s.name.as_bytes());
        let g = &s.gaussians;
        for x in &s.shape {
            h.update(&x.to_le_bytes());
        }
        for v in &s.static_offset {
            for x in v.to_array() {
                h.update(&x.to_le_bytes());
            }
        }
        for (i, b) in g.binding.iter().enumerate() {
            h.update(&b.to_le_bytes());
            for x in g.position[i]
                .to_array()
                .into_iter()
                .chain(g.rotation[i].to_array())
                .chain(g.log_scale[i].to_array())
            {
                h.update(&x.to_le_bytes());
            }
            h.update(&g.opacity_logit[i].to_le_bytes());
        }
        for x in &g.sh {
            h.update(&x.to_le_bytes());
        }
    }
    h.finalize()
}

#[test]
fn same_seed_gives_identical_bytes_and_another_seed_differs() {
    let a = db(7, 12_000, 3);
    let b = db(7, 12_000, 3);
    let c = db(8, 12_000, 3);
    assert_eq!(fingerprint(&a), fingerprint(&b));
    assert_ne!(fingerprint(&a), fingerprint(&c));
}

#[test]
fn default_database_has_14_sources_of_tens_of_thousands_of_gaussians() {
    let d = db(1, SyntheticOptions::default().gaussians_per_avatar, 14);
    assert_eq!(d.sources.len(), 14);
    let names: std::collections::HashSet<_> = d.sources.iter().map(|s| s.name.clone()).collect();
    assert_eq!(names.len(), 14, "names are unique");
    for s in &d.sources {
        assert!(
            (40_000..=100_000).contains(&s.gaussians.len()),
            "{}: {}",
            s.name,
            s.gaussians.len()
        );
        assert_eq!(s.gaussians.sh_degree, 3);
        s.gaussians.validate(d.model.triangle_count()).unwrap();
        assert!(s.motion.frames() >= 110);
    }
    assert!(d.motions.len() >= 4 && d.motions.iter().all(|m| m.frames() >= 110));
}

#[test]
fn every_triangle_carries_gaussians_that_sit_on_it() {
    let d = db(3, 15_000, 2);
    let s = &d.sources[1];
    let mut per_triangle = vec![0usize; d.model.triangle_count()];
    for &b in &s.gaussians.binding {
        per_triangle[b as usize] += 1;
    }
    assert!(
        per_triangle.iter().all(|&n| n >= 1),
        "GaussianAvatars keeps one per triangle"
    );
    // Gaussians lie near their parent triangle: local position within a few triangle sizes.
    let frames = triangle_frames(&s.neutral(&d.model), &d.model.triangles);
    for i in 0..s.gaussians.len() {
        let local = s.gaussians.position[i];
        assert!(
            local.length() < 3.0,
            "Gaussian {i} is far from its triangle: {local}"
        );
        assert!(frames[s.gaussians.binding[i] as usize].scale > 0.0);
    }
}

#[test]
fn sources_differ_in_shape_and_colour() {
    let d = db(1, 6_000, 14);
    let dc_mean = |k: usize| {
        let g = &d.sources[k].gaussians;
        let stride = g.sh_stride();
        (0..g.len()).map(|i| g.sh[i * stride]).sum::<f32>() / g.len() as f32
    };
    // Skin from light to dark: the first source is brighter on average than the last.
    assert!(dc_mean(0) > dc_mean(13) + 0.5);
    assert_ne!(d.sources[0].shape, d.sources[1].shape);
}

#[test]
fn too_many_sources_is_a_clear_error() {
    let err = builtin_database(
        build_head(),
        SyntheticOptions {
            sources: 15,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(err.contains("1 to 14"), "{err}");
}
