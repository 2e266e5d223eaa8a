"""UsdPreviewSurface materials with UsdUVTexture inputs.

Colour spaces: the albedo / base-colour image is sRGB (`sourceColorSpace = "sRGB"`); data maps (roughness,
metallic-roughness, normal) are read `raw`. A metallic-roughness image uses glTF's channel layout (G roughness,
B metallic), so one file feeds two inputs. Texture paths are relative asset paths (anchored at the layer that
holds the material). UV convention: `st` with (0, 0) at the bottom-left of the image, as USD and OBJ use.
"""

from __future__ import annotations

from dataclasses import dataclass

from pxr import Gf, Sdf, Usd, UsdShade

from darthand.textures.loader import SKIN_COLOR, SKIN_ROUGHNESS


@dataclass(frozen=True)
class MaterialSpec:
    """A surface description: textures as relative asset paths (None: use the constant), constants as fallbacks.

    albedo: sRGB colour image; roughness: single-channel data map (red channel read); metallic_roughness: glTF
    layout data map (G roughness, B metallic); normal: tangent-space normal map (raw, [0, 1] -> [-1, 1]).
    The constants default to the untextured skin (textures.loader.SKIN_COLOR, SKIN_ROUGHNESS).
    """

    albedo: str | None = None
    roughness: str | None = None
    metallic_roughness: str | None = None
    normal: str | None = None
    base_color: tuple[float, float, float] = SKIN_COLOR
    roughness_value: float = SKIN_ROUGHNESS
    metallic_value: float = 0.0
    wrap: str = "repeat"

    @property
    def textures(self) -> list[str]:
        return [p for p in (self.albedo, self.roughness, self.metallic_roughness, self.normal) if p]


def define_material(stage: Usd.Stage, path: Sdf.Path, spec: MaterialSpec) -> UsdShade.Material:
    """A Material at `path` whose surface is a UsdPreviewSurface fed by UsdUVTexture shaders reading `st`."""
    material = UsdShade.Material.Define(stage, path)
    surface = _shader(stage, path.AppendChild("PreviewSurface"), "UsdPreviewSurface")
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    surface.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(0)
    diffuse = surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
    rough = surface.CreateInput("roughness", Sdf.ValueTypeNames.Float)
    metal = surface.CreateInput("metallic", Sdf.ValueTypeNames.Float)
    diffuse.Set(Gf.Vec3f(*spec.base_color))
    rough.Set(float(spec.roughness_value))
    metal.Set(float(spec.metallic_value))
    if not spec.textures:
        return material

    reader = _shader(stage, path.AppendChild("StReader"), "UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)

    def texture(name: str, asset: str, color_space: str) -> UsdShade.Shader:
        tex = _shader(stage, path.AppendChild(name), "UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(asset))
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(color_space)
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(spec.wrap)
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(spec.wrap)
        return tex

    if spec.albedo:
        tex = texture("AlbedoTexture", spec.albedo, "sRGB")
        diffuse.ConnectToSource(tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    if spec.metallic_roughness:
        tex = texture("MetallicRoughnessTexture", spec.metallic_roughness, "raw")
        rough.ConnectToSource(tex.CreateOutput("g", Sdf.ValueTypeNames.Float))
        metal.ConnectToSource(tex.CreateOutput("b", Sdf.ValueTypeNames.Float))
    elif spec.roughness:
        tex = texture("RoughnessTexture", spec.roughness, "raw")
        rough.ConnectToSource(tex.CreateOutput("r", Sdf.ValueTypeNames.Float))
    if spec.normal:
        tex = texture("NormalTexture", spec.normal, "raw")
        tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(2, 2, 2, 1))
        tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(-1, -1, -1, 0))
        surface.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(
            tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    return material


def bind_material(prim: Usd.Prim, material_path: Sdf.Path) -> None:
    """Direct material binding of `prim` to `material_path` (which may be composed in later, e.g. by a variant)."""
    UsdShade.MaterialBindingAPI.Apply(prim).GetDirectBindingRel().SetTargets([material_path])


def _shader(stage: Usd.Stage, path: Sdf.Path, shader_id: str) -> UsdShade.Shader:
    shader = UsdShade.Shader.Define(stage, path)
    shader.CreateIdAttr(shader_id)
    return shader
