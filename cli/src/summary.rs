//! Particle-count wording shared by `run`, `demo` and `watch`. A leaf, for
//! the same reason as `server_arg.rs`.

/// A particle count for the summaries of `run`, `demo` and `watch`,
/// split into fluid and solid particles when the scene has elastic solids
/// (`solids`: each solid's count), since the two move so differently.
pub(crate) fn particle_summary(total: u64, solids: &[u64]) -> String {
    if solids.is_empty() {
        return total.to_string();
    }
    let in_solids: u64 = solids.iter().sum();
    let plural = if solids.len() == 1 { "" } else { "s" };
    format!(
        "{total}  ({} fluid, {in_solids} in {} solid{plural})",
        total.saturating_sub(in_solids),
        solids.len()
    )
}

#[cfg(test)]
mod tests {
    use super::particle_summary;

    #[test]
    fn summaries_split_solid_particles_from_the_fluid() {
        assert_eq!(particle_summary(125, &[]), "125");
        assert_eq!(
            particle_summary(300, &[100, 50]),
            "300  (150 fluid, 150 in 2 solids)"
        );
        assert_eq!(particle_summary(40, &[40]), "40  (0 fluid, 40 in 1 solid)");
    }
}
