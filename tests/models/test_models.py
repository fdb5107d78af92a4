"""Reference models: dual-head TimeSformer (masked loss, shapes, configs) and ResNet-50 tools."""

from __future__ import annotations

import pytest
import torch

from vtsbench.errors import VtsError
from vtsbench.models.resnet import grad_cam, static_resnet, write_gradcam_overlays
from vtsbench.models.timesformer import (
    DualHeadTimesformer,
    PretrainedWeightsMissing,
    adapt_patch_weight,
    backbone_config,
    load_pretrained_backbone,
    masked_joint_loss,
    parameter_counts,
)
from vtsbench.transforms.augment import augment

T, S = 2, 32  # tiny sequences: 2 frames of 32x32 with patch 16


def tiny(modality: str = "rgb", seed: int = 0) -> DualHeadTimesformer:
    torch.manual_seed(seed)
    return DualHeadTimesformer.from_config("small", modality, image_size=S, num_frames=T)


def grads(model, x, state, direction, lam=1.0):
    model.zero_grad()
    s, d = model(x)
    masked_joint_loss(s, d, state, direction, lam).backward()
    return {n: p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}


@pytest.fixture(scope="module")
def tiny_rgb():
    return tiny("rgb")


def test_masked_loss_ignores_garbage_directions_of_non_slip(tiny_rgb):
    torch.manual_seed(1)
    x = torch.randn(4, T, 3, S, S)
    state = torch.tensor([0, 2, 1, 2])
    g_ref = grads(tiny_rgb, x, state, torch.tensor([-1, 3, 99, 5]))
    for garbage in ([7, 3, -5, 5], [0, 3, 0, 5], [12345, 3, -1, 5]):
        g = grads(tiny_rgb, x, state, torch.tensor(garbage))
        assert g.keys() == g_ref.keys()
        for name in g_ref:
            assert torch.equal(g[name], g_ref[name]), name
    # the direction head gets gradient from the slip samples
    assert g_ref["direction_head.weight"].abs().sum() > 0


def test_direction_of_slip_sample_changes_gradients(tiny_rgb):
    torch.manual_seed(2)
    x = torch.randn(3, T, 3, S, S)
    state = torch.tensor([0, 2, 1])
    g1 = grads(tiny_rgb, x, state, torch.tensor([99, 1, -1]))
    g2 = grads(tiny_rgb, x, state, torch.tensor([99, 6, -1]))
    assert not torch.equal(g1["direction_head.weight"], g2["direction_head.weight"])
    assert not torch.equal(g1["backbone.embeddings.cls_token"], g2["backbone.embeddings.cls_token"])
    g3 = grads(tiny_rgb, x, state, torch.tensor([99, 1, -1]), lam=0.0)
    assert not torch.equal(g1["backbone.embeddings.cls_token"], g3["backbone.embeddings.cls_token"])


def test_masked_loss_formula():
    torch.manual_seed(3)
    s, d = torch.randn(5, 3), torch.randn(5, 8)
    state = torch.tensor([0, 1, 0, 1, 1])
    ce = torch.nn.functional.cross_entropy
    loss = masked_joint_loss(s, d, state, torch.tensor([-1, 99, 8, -7, 1000]), lam=2.0)
    assert torch.allclose(loss, ce(s, state))
    state = torch.tensor([2, 1, 2, 0, 0])
    direction = torch.tensor([3, -1, 7, 99, 8])
    loss = masked_joint_loss(s, d, state, direction, lam=0.5)
    expected = ce(s, state) + 0.5 * ce(d[[0, 2]], direction[[0, 2]])
    assert torch.allclose(loss, expected)


def test_no_slip_batch_gives_no_direction_gradient(tiny_rgb):
    x = torch.randn(2, T, 3, S, S)
    g = grads(tiny_rgb, x, torch.tensor([0, 1]), torch.tensor([-1, 99]))
    assert torch.count_nonzero(g["direction_head.weight"]) == 0


@pytest.mark.parametrize("modality,channels", [("rgb", 3), ("depth", 1), ("rgbd", 4)])
def test_timesformer_shapes(modality, channels):
    model = tiny(modality).eval()
    with torch.no_grad():
        s, d = model(torch.randn(2, T, channels, S, S))
    assert s.shape == (2, 3) and d.shape == (2, 8)
    with pytest.raises(ValueError):
        model(torch.randn(2, T, 2, S, S))


def test_parameter_counts_on_meta_device():
    counts = parameter_counts("rgb")
    assert 120e6 < counts["paper"]["backbone"] < 122.5e6
    assert counts["paper"]["heads"] == 768 * 11 + 11
    assert counts["small"]["total"] < 5e6
    cfg = backbone_config("paper")
    assert (cfg.image_size, cfg.num_frames, cfg.patch_size, cfg.hidden_size) == (224, 8, 16, 768)
    assert cfg.attention_type == "divided_space_time"


def test_missing_pretrained_weights_is_a_clear_error(tmp_path):
    with pytest.raises(PretrainedWeightsMissing, match="small"):
        DualHeadTimesformer.from_config("paper", "rgb", pretrained_path=tmp_path / "nope")
    cfg = backbone_config("small", "rgb", image_size=S, num_frames=T)
    with pytest.raises(PretrainedWeightsMissing) as info:
        load_pretrained_backbone(cfg, None, cache_dir=tmp_path)
    assert "\n" not in str(info.value)
    with pytest.raises(VtsError):
        DualHeadTimesformer.from_config("huge")


@pytest.mark.parametrize("modality", ["depth", "rgbd"])
def test_pretrained_three_channel_weights_adapt(tmp_path, modality):
    src = tiny("rgb", seed=5)
    src.backbone.save_pretrained(tmp_path / "ckpt")
    model = DualHeadTimesformer.from_config(
        "small", modality, pretrained_path=tmp_path / "ckpt", image_size=S, num_frames=T
    )
    key = "embeddings.patch_embeddings.projection.weight"
    w3 = src.backbone.state_dict()[key]
    w = model.backbone.state_dict()[key]
    assert torch.allclose(w, adapt_patch_weight(w3, w.shape[1]))
    if modality == "rgbd":
        assert torch.equal(w[:, :3], w3)
    other = "encoder.layer.0.attention.attention.qkv.weight"
    assert torch.equal(model.backbone.state_dict()[other], src.backbone.state_dict()[other])


@pytest.fixture(scope="module")
def resnet_rgb():
    torch.manual_seed(0)
    return static_resnet(15, "rgb").eval()


@pytest.mark.parametrize("modality,channels", [("rgb", 3), ("depth", 1)])
def test_resnet_shapes(modality, channels, resnet_rgb):
    model = resnet_rgb if modality == "rgb" else static_resnet(15, modality).eval()
    with torch.no_grad():
        out = model(torch.rand(2, channels, 64, 64))
    assert out.shape == (2, 15)
    assert model.conv1.in_channels == channels


def test_resnet_pretrained_file(tmp_path):
    with pytest.raises(VtsError, match="not found"):
        static_resnet(15, "rgb", pretrained_path=tmp_path / "missing.pth")
    from torchvision.models import resnet50

    ref = resnet50(weights=None)
    torch.save(ref.state_dict(), tmp_path / "r50.pth")
    model = static_resnet(4, "depth", pretrained_path=tmp_path / "r50.pth")
    assert torch.equal(model.layer1[0].conv1.weight, ref.layer1[0].conv1.weight)
    assert torch.allclose(model.conv1.weight, ref.conv1.weight.mean(1, keepdim=True))
    assert model.fc.out_features == 4
    with pytest.raises(VtsError):
        static_resnet(15, "rgbd")


def test_grad_cam_maps_and_overlays(tmp_path, resnet_rgb):
    torch.manual_seed(4)
    x = torch.rand(2, 3, 64, 64)
    before = [p.grad for p in resnet_rgb.parameters()]
    cams = grad_cam(resnet_rgb, x)
    assert cams.shape == (2, 64, 64)
    assert torch.isfinite(cams).all() and cams.min() >= 0 and cams.max() <= 1
    assert all(
        b is None and p.grad is None for b, p in zip(before, resnet_rgb.parameters(), strict=True)
    )
    cams_t = grad_cam(resnet_rgb, x, target=[3, 7])
    assert cams_t.shape == (2, 64, 64)
    paths = write_gradcam_overlays(x, cams, [tmp_path / "a.png", tmp_path / "sub" / "b.png"])
    from tests.fixtures.figures import png_dpi

    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert round(png_dpi(p)[0]) == 150  # print resolution stated in the PNG
    depth = torch.rand(1, 1, 64, 64)
    (p,) = write_gradcam_overlays(depth, cams[:1], [tmp_path / "d.png"])
    assert p.stat().st_size > 0


@pytest.mark.parametrize("modality,channels", [("rgb", 3), ("depth", 1), ("rgbd", 4)])
def test_augment_deterministic(modality, channels):
    batch = torch.rand(3, channels, 32, 32)
    a = augment(batch, modality, torch.Generator().manual_seed(7))
    b = augment(batch, modality, torch.Generator().manual_seed(7))
    c = augment(batch, modality, torch.Generator().manual_seed(8))
    assert a.shape == batch.shape and torch.equal(a, b) and not torch.equal(a, c)


def test_augment_leaves_depth_values_unjittered():
    depth = torch.full((4, 1, 32, 32), 0.7)
    out = augment(depth, "depth", torch.Generator().manual_seed(0), max_rotation=0.0)
    assert torch.allclose(out, depth)  # no rotation: only flips and crops of a constant map
    rgbd = torch.cat([torch.full((4, 3, 32, 32), 0.5), depth], dim=1)
    out = augment(rgbd, "rgbd", torch.Generator().manual_seed(0), max_rotation=0.0)
    assert torch.allclose(out[:, 3], depth[:, 0])
    assert not torch.allclose(out[:, :3], rgbd[:, :3])  # colour is jittered


def test_flip_augment_mirrors_frames_and_maps_directions() -> None:
    from vtsbench.labels import MIRROR_X, MIRROR_Y
    from vtsbench.transforms.symmetry import flip_augment

    x = torch.arange(16 * 2 * 1 * 3 * 4, dtype=torch.float32).view(16, 2, 1, 3, 4)
    d = torch.tensor([0, 1, 2, 3, 4, 5, 6, 7, -1, -1, 0, 1, 2, 3, 4, 5])
    y, e = flip_augment(x, d, torch.Generator().manual_seed(0))
    y2, e2 = flip_augment(x, d, torch.Generator().manual_seed(0))
    assert torch.equal(y, y2) and torch.equal(e, e2)  # deterministic given the generator
    seen = set()
    for i in range(16):
        variants = {(fx, fy): x[i].flip(-1) if fx else x[i] for fx in (0, 1) for fy in (0, 1)}
        variants = {key: v.flip(-2) if key[1] else v for key, v in variants.items()}
        (fx, fy), = [key for key, v in variants.items() if torch.equal(y[i], v)]
        seen.add((fx, fy))
        k = int(d[i])
        if k < 0:
            assert int(e[i]) == k
            continue
        if fx:
            k = MIRROR_X[k]
        if fy:
            k = MIRROR_Y[k]
        assert int(e[i]) == k
    assert len(seen) > 1  # both flipped and unflipped samples occur


def test_resnet18_arch_and_unknown_arch() -> None:
    m = static_resnet(5, "rgb", arch="resnet18")
    assert m(torch.zeros(1, 3, 64, 64)).shape == (1, 5)
    assert sum(p.numel() for p in m.parameters()) < 12_000_000
    with pytest.raises(VtsError, match="arch"):
        static_resnet(5, "rgb", arch="vgg")


def test_augment_border_fill_keeps_the_gel_colour_in_turned_corners():
    # a grey-green gel with a dark imprint in the middle: a turn by about 45 degrees uncovers
    # the corners, which `border` fills with the gel's colour and `zero` with black
    img = torch.empty(1, 3, 32, 32)
    img[:, 0], img[:, 1], img[:, 2] = 0.4, 0.6, 0.5
    img[:, :, 12:20, 12:20] = 0.1
    batch = img.repeat(8, 1, 1, 1)
    kw = dict(jitter=0.0, max_rotation=50.0, crop_scale=(1.0, 1.0))
    border = augment(batch, "rgb", torch.Generator().manual_seed(3), fill="border", **kw)
    zero = augment(batch, "rgb", torch.Generator().manual_seed(3), **kw)
    gel = img[0, :, 0, 0].view(1, 3)
    assert zero[:, :, 0, 0].min() < 0.05  # black corners somewhere in the batch
    # (bilinear resampling darkens the seam between the frame and the fill a little)
    assert torch.allclose(border[:, :, 0, 0], gel.expand(8, 3), atol=0.05)
    with pytest.raises(ValueError, match="fill"):
        augment(batch, "rgb", torch.Generator(), fill="mean")
