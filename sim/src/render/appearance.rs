//! Surface appearance parameters for the shading model, and the defaults per material class.

use perception::part::Material;

/// Parameters of the microfacet shading model for one surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Appearance {
    /// Base colour in linear RGB, 0–1 (albedo for dielectrics, F0 for metals).
    pub base_color: [f64; 3],
    /// 0 for dielectrics, 1 for metals.
    pub metallic: f64,
    /// GGX roughness (perceptual, squared for alpha), 0.02–1.
    pub roughness: f64,
    /// Specular reflectance at normal incidence for dielectrics (0.04 typical).
    pub specular: f64,
    /// Brushing: 0 isotropic, up to 1 for highlights stretched across the brushing direction
    /// (the part's x axis), as on brushed sheet metal.
    pub anisotropy: f64,
}

impl Appearance {
    /// The nominal appearance of a material class.
    pub fn for_material(material: Material) -> Self {
        match material {
            // Brushed nickel-plated steel: bright, moderately rough metal, lightly brushed.
            Material::Metal => Self {
                base_color: [0.66, 0.65, 0.62],
                metallic: 1.0,
                roughness: 0.35,
                specular: 0.04,
                anisotropy: 0.3,
            },
            Material::DarkPlastic => Self {
                base_color: [0.035, 0.035, 0.04],
                metallic: 0.0,
                roughness: 0.45,
                specular: 0.045,
                anisotropy: 0.0,
            },
            Material::Gold => Self {
                base_color: [1.0, 0.77, 0.34],
                metallic: 1.0,
                roughness: 0.25,
                specular: 0.04,
                anisotropy: 0.0,
            },
            // The white print of the tag board (the black print is `TagBoard::black`).
            Material::TagBoard => Self {
                base_color: [0.78, 0.78, 0.76],
                metallic: 0.0,
                roughness: 0.6,
                specular: 0.04,
                anisotropy: 0.0,
            },
            Material::Aluminium => Self {
                base_color: [0.91, 0.92, 0.92],
                metallic: 1.0,
                roughness: 0.5,
                specular: 0.04,
                anisotropy: 0.0,
            },
        }
    }

    /// Multiplies the base colour by a tint (per channel) and replaces the roughness.
    pub fn tinted(self, tint: [f64; 3], roughness: f64) -> Self {
        Self {
            base_color: [
                (self.base_color[0] * tint[0]).clamp(0.0, 1.0),
                (self.base_color[1] * tint[1]).clamp(0.0, 1.0),
                (self.base_color[2] * tint[2]).clamp(0.0, 1.0),
            ],
            roughness: roughness.clamp(0.02, 1.0),
            ..self
        }
    }
}
