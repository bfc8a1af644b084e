//! Radiosity over [`Patches`](crate::patches::Patches): B = ρ·(E + Σ F·B), with E the direct
//! irradiance from the lights and F the form factors between elements.
//!
//! Form factors ([`element_form_factor`]) integrate the exact point-to-polygon
//! form factor over the receiver with one Gauss rule for all pairs, so they
//! stay finite for touching elements and the factors out of a receiver in a
//! closed room sum to one (a receiver lying across a one-sided source's
//! plane is integrated over the source instead: a step across it would
//! otherwise fall between its Gauss points); visibility is the fraction of
//! Embree rays between the two elements that pass.
//!
//! [`Transport`] is either the full patch-to-patch matrix (small scenes, and
//! the test oracle) or hierarchical radiosity (Hanrahan et al. 1991, Loscos
//! §2.3): links between elements at the level an oracle deems accurate,
//! gathered at each level, irradiance pushed down and radiosity pulled up.
//! [`solve`] solves (I − ρT)B = b by restarted GMRES: the plain gather
//! iteration ([`solve_by_iteration`]) needs ~ln(tol)/ln(ρ) sweeps, hundreds
//! at ρ = 0.99, where GMRES needs a handful.
//!
//! Its parts: `transport` (the matrix or the links, refined by the oracle),
//! `form_factor` (factors and visibility), `gather_rows` (rows of weights
//! gathered by rays: the objects in the texture path's transport),
//! `direct` (the lights' irradiance), `solve` (GMRES), `change` and
//! `near` / `near_pixel` (what the room sees of the objects, per patch,
//! per near-grid cell and per pixel).

mod change;
mod direct;
mod form_factor;
mod gather_rows;
mod near;
mod near_pixel;
mod object_albedo;
mod solve;
mod still;
mod transport;

pub use change::{ObjectView, cosine_direction, solve_change};
pub use direct::{
    DirectWithObjects, direct_irradiance, direct_irradiance_with_objects, total_direct,
};
pub use form_factor::{PairShafts, element_form_factor, visibility};
pub use gather_rows::{GatherRows, GatherRowsSettings, ObjectLinkEstimate};
pub use near::{NearField, NearView, ReadPoints};
pub use near_pixel::ChangeSampler;
pub use object_albedo::object_reflectances;
pub(crate) use solve::solve_from;
pub use solve::{Solution, solve, solve_by_iteration};
pub use still::StillSurfaces;
pub use transport::{DEFAULT_LINK_EPSILON, Link, SourceLink, Transport};

#[cfg(test)]
mod tests;
