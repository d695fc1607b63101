//! The view parameters every renderer shares, declared once: the camera, the light, the
//! texture's tiling, the scene's scale (`mm_per_unit`), the background and the shadows. A render
//! kind declares its `Params` through [`view_params!`], naming the shared fields it takes; each
//! one's type, documentation, schema range and default come from here. A kind whose default must
//! differ says so where it names the field (`shadows = true`), so no default differs silently.
//! The parameters stay flat in the graph file (`"camera"`, `"tiling"`, … beside the kind's own),
//! so version-1 graphs need no migration.
//!
//! Each `Params` gets `VIEW_FIELDS`, the shared fields it has, in this order: the planner's probe
//! copies exactly those from a render node to `scene.footprint`.

/// The shared fields, in the order `VIEW_FIELDS` lists them.
pub const ALL: [&str; 7] = [
    "camera",
    "light",
    "tiling",
    "mm_per_unit",
    "background",
    "shadows",
    "shadow_resolution",
];

/// The default tiling: four tiles across each unit of texture coordinate.
pub const TILING: [f64; 2] = [4.0, 4.0];
/// The default scale: a world unit is a centimetre.
pub const MM_PER_UNIT: f64 = 10.0;
/// The default shadow map's size per side.
pub const SHADOW_RESOLUTION: u32 = 1024;

/// Declares a render kind's `Params`: the shared view fields listed in `view { … }` (any of
/// [`ALL`], each optionally `= default`), then the kind's own fields, each `pub name: Type =
/// default,` with its doc comment and attributes. Generates the struct (the attributes written
/// before `pub struct` apply), its `Default` and `VIEW_FIELDS`.
#[macro_export]
macro_rules! view_params {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            view { $($shared:tt)* }
            $($own:tt)*
        }
    ) => {
        $crate::view_params!(@munch [$(#[$meta])* pub struct $name] [] [] [] [$($shared)*] $($own)*);
    };

    (@munch $hdr:tt [$($f:tt)*] [$($d:tt)*] [$($n:tt)*]
        [camera $(= $o:expr)? $(, $($more:tt)*)?] $($own:tt)*) => {
        $crate::view_params!(@munch $hdr
            [$($f)*
             /// Pinhole (`fov`) or orthographic camera, looking from `eye` at `target`.
             pub camera: $crate::support::raytrace::camera::CameraParams,]
            [$($d)* camera: $crate::view_params!(@or ($crate::support::raytrace::camera::CameraParams::default()) $(($o))?),]
            [$($n)* "camera",]
            [$($($more)*)?] $($own)*);
    };
    (@munch $hdr:tt [$($f:tt)*] [$($d:tt)*] [$($n:tt)*]
        [light $(= $o:expr)? $(, $($more:tt)*)?] $($own:tt)*) => {
        $crate::view_params!(@munch $hdr
            [$($f)*
             /// A directional light, a point light with `position`, or an environment (`environment`,
             /// `sky` or `studio`) where the node shades one.
             pub light: $crate::support::raytrace::light::LightParams,]
            [$($d)* light: $crate::view_params!(@or ($crate::support::raytrace::light::LightParams::default()) $(($o))?),]
            [$($n)* "light",]
            [$($($more)*)?] $($own)*);
    };
    (@munch $hdr:tt [$($f:tt)*] [$($d:tt)*] [$($n:tt)*]
        [tiling $(= $o:expr)? $(, $($more:tt)*)?] $($own:tt)*) => {
        $crate::view_params!(@munch $hdr
            [$($f)*
             /// Texture tiles per unit of texture coordinate, [along u, along v].
             pub tiling: [f64; 2],]
            [$($d)* tiling: $crate::view_params!(@or ($crate::support::raytrace::view::TILING) $(($o))?),]
            [$($n)* "tiling",]
            [$($($more)*)?] $($own)*);
    };
    (@munch $hdr:tt [$($f:tt)*] [$($d:tt)*] [$($n:tt)*]
        [mm_per_unit $(= $o:expr)? $(, $($more:tt)*)?] $($own:tt)*) => {
        $crate::view_params!(@munch $hdr
            [$($f)*
             /// Millimetres per world unit of the mesh (10⁻⁹ to 10⁹): the scale of a medium's
             /// coefficients (mm⁻¹) and of the footprint metrics in mm. Beyond the range, areas
             /// in mm² overflow the f32 the GPU sums in.
             #[schemars(range(min = 1e-9, max = 1e9))]
             pub mm_per_unit: f64,]
            [$($d)* mm_per_unit: $crate::view_params!(@or ($crate::support::raytrace::view::MM_PER_UNIT) $(($o))?),]
            [$($n)* "mm_per_unit",]
            [$($($more)*)?] $($own)*);
    };
    (@munch $hdr:tt [$($f:tt)*] [$($d:tt)*] [$($n:tt)*]
        [background $(= $o:expr)? $(, $($more:tt)*)?] $($own:tt)*) => {
        $crate::view_params!(@munch $hdr
            [$($f)*
             /// Linear RGB where nothing is hit.
             pub background: [f64; 3],]
            [$($d)* background: $crate::view_params!(@or ([0.0; 3]) $(($o))?),]
            [$($n)* "background",]
            [$($($more)*)?] $($own)*);
    };
    (@munch $hdr:tt [$($f:tt)*] [$($d:tt)*] [$($n:tt)*]
        [shadows $(= $o:expr)? $(, $($more:tt)*)?] $($own:tt)*) => {
        $crate::view_params!(@munch $hdr
            [$($f)*
             /// Shadows from the light: a shadow map of what the light sees (`render.mesh`: of
             /// the MDF-displaced surface; `sss.render`, `qh.render`: of the mesh, so surface the
             /// light does not reach receives only light transmitted through the material), or
             /// for `render.relief` a search towards the light through the height field.
             pub shadows: bool,]
            [$($d)* shadows: $crate::view_params!(@or (false) $(($o))?),]
            [$($n)* "shadows",]
            [$($($more)*)?] $($own)*);
    };
    (@munch $hdr:tt [$($f:tt)*] [$($d:tt)*] [$($n:tt)*]
        [shadow_resolution $(= $o:expr)? $(, $($more:tt)*)?] $($own:tt)*) => {
        $crate::view_params!(@munch $hdr
            [$($f)*
             /// Shadow map size in texels (square).
             #[schemars(range(min = 1, max = 16384))]
             pub shadow_resolution: u32,]
            [$($d)* shadow_resolution: $crate::view_params!(@or ($crate::support::raytrace::view::SHADOW_RESOLUTION) $(($o))?),]
            [$($n)* "shadow_resolution",]
            [$($($more)*)?] $($own)*);
    };

    // Every shared field taken: the struct, its defaults and its list of shared fields.
    (@munch [$(#[$meta:meta])* pub struct $name:ident] [$($f:tt)*] [$($d:tt)*] [$($n:tt)*] []
        $(
            $(#[$fmeta:meta])*
            pub $field:ident : $ty:ty = $default:expr,
        )*
    ) => {
        $(#[$meta])*
        pub struct $name {
            $($f)*
            $(
                $(#[$fmeta])*
                pub $field: $ty,
            )*
        }

        impl Default for $name {
            fn default() -> Self {
                $name {
                    $($d)*
                    $($field: $default,)*
                }
            }
        }

        impl $name {
            /// The shared view fields (`raytrace::view`) these parameters have.
            pub const VIEW_FIELDS: &'static [&'static str] = &[$($n)*];
        }
    };

    (@or ($default:expr)) => { $default };
    (@or ($default:expr) ($over:expr)) => { $over };
}

#[cfg(test)]
mod tests {
    use crate::support::raytrace::camera::CameraParams;
    use schemars::JsonSchema;
    use serde::{Deserialize, Serialize};

    crate::view_params! {
        /// A kind with part of the view and a default of its own.
        #[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
        #[serde(default, deny_unknown_fields)]
        pub struct Example {
            view { camera, tiling = [1.0, 1.0], mm_per_unit, shadows = true }
            /// Its own field.
            #[schemars(range(min = 1, max = 8))]
            pub steps: u32 = 3,
        }
    }

    #[test]
    fn shared_fields_keep_their_definition_and_take_an_explicit_default() {
        let e = Example::default();
        assert_eq!(e.tiling, [1.0, 1.0]);
        assert_eq!(e.mm_per_unit, super::MM_PER_UNIT);
        assert!(e.shadows);
        assert_eq!(e.steps, 3);
        assert_eq!(e.camera.resolution, CameraParams::default().resolution);
        assert_eq!(
            Example::VIEW_FIELDS,
            ["camera", "tiling", "mm_per_unit", "shadows"]
        );
        // Flat in the file, unknown fields refused, the shared range in the schema.
        let parsed: Example = serde_json::from_str(r#"{"mm_per_unit": 20, "steps": 5}"#).unwrap();
        assert_eq!(
            (parsed.mm_per_unit, parsed.steps, parsed.tiling),
            (20.0, 5, [1.0, 1.0])
        );
        assert!(serde_json::from_str::<Example>(r#"{"light": {}}"#).is_err());
        let schema = serde_json::to_value(schemars::schema_for!(Example)).unwrap();
        let mm = &schema["properties"]["mm_per_unit"];
        assert_eq!(mm["minimum"], 1e-9, "{schema}");
        assert!(mm["description"]
            .as_str()
            .unwrap()
            .contains("Millimetres per world unit"));
    }
}
