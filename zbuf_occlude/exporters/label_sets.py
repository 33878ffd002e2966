"""The label sets of pretrained networks: which id each class name has, so that an export's labels
match a network trained on ModelNet40, ModelNet10 or ShapeNet-55.

A label is the class's line in the set's class list (``shape_names.txt``); ``own`` numbers the data
set's own classes (its ``shape_names.txt``).  A class the chosen set lacks is refused by name.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.protocols.modelnet40c import MODELNET40_CLASSES

__all__ = ["LABEL_SETS", "MODELNET10_CLASSES", "SHAPENET55", "LabelSet", "label_set", "shapenet_synset"]

#: ModelNet10's ``modelnet10_shape_names.txt`` (Wu et al. 2015; Pointnet_Pointnet2_pytorch's list).
MODELNET10_CLASSES = ("bathtub", "bed", "chair", "desk", "dresser", "monitor", "night_stand", "sofa", "table", "toilet")

#: ShapeNetCore v2's 55 synsets, ``(synset id, names)``, the first name as PCN's ``taxonomy_name``
#: and the others as the ``taxonomy.json`` synonyms a folder may be named by; in synset order,
#: which is the label order of ShapeNet-55 (Yu et al., PoinTr, ICCV 2021).
SHAPENET55: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("02691156", ("airplane", "aeroplane", "plane")), ("02747177", ("trash bin", "ashcan", "trash can", "garbage can", "wastebin")),
    ("02773838", ("bag", "traveling bag", "handbag")), ("02801938", ("basket", "handbasket")),
    ("02808440", ("bathtub", "bathing tub", "bath", "tub")), ("02818832", ("bed",)), ("02828884", ("bench",)),
    ("02843684", ("birdhouse",)), ("02871439", ("bookshelf",)), ("02876657", ("bottle",)), ("02880940", ("bowl",)),
    ("02924116", ("bus", "autobus")), ("02933112", ("cabinet",)), ("02942699", ("camera", "photographic camera")),
    ("02946921", ("can", "tin", "tin can")), ("02954340", ("cap",)), ("02958343", ("car", "auto", "automobile")),
    ("02992529", ("cellphone", "cellular telephone", "cellular phone", "mobile phone")), ("03001627", ("chair",)),
    ("03046257", ("clock",)), ("03085013", ("keyboard", "computer keyboard", "keypad")),
    ("03207941", ("dishwasher", "dish washer", "dishwashing machine")), ("03211117", ("display", "video display", "monitor")),
    ("03261776", ("earphone", "earpiece", "headphone")), ("03325088", ("faucet", "spigot")),
    ("03337140", ("file cabinet", "file", "filing cabinet")), ("03467517", ("guitar",)), ("03513137", ("helmet",)),
    ("03593526", ("jar",)), ("03624134", ("knife",)), ("03636649", ("lamp",)), ("03642806", ("laptop", "laptop computer")),
    ("03691459", ("loudspeaker", "speaker", "speaker system")), ("03710193", ("mailbox", "letter box")),
    ("03759954", ("microphone", "mike")), ("03761084", ("microwave", "microwave oven")),
    ("03790512", ("motorbike", "motorcycle", "bike")), ("03797390", ("mug",)),
    ("03928116", ("piano", "pianoforte", "forte-piano")), ("03938244", ("pillow",)),
    ("03948459", ("pistol", "handgun", "side arm")), ("03991062", ("flowerpot", "pot", "flower_pot")),
    ("04004475", ("printer", "printing machine")), ("04074963", ("remote", "remote control")), ("04090263", ("rifle",)),
    ("04099429", ("rocket", "projectile")), ("04225987", ("skateboard",)), ("04256520", ("sofa", "couch", "lounge")),
    ("04330267", ("stove",)), ("04379243", ("table",)), ("04401088", ("telephone", "phone", "telephone set")),
    ("04460130", ("tower",)), ("04468005", ("train", "railroad train")), ("04530566", ("watercraft", "vessel")),
    ("04554684", ("washer", "automatic washer", "washing machine")),
)  # fmt: skip


def shapenet_synset(class_name: str) -> str | None:
    """The ShapeNet synset id of ``class_name`` (a synset id itself, or any of its names, case and
    ``_``/space alike); ``None`` when it is none of ShapeNet-55's."""
    key = class_name.strip().lower().replace("_", " ")
    for synset, names in SHAPENET55:
        if key == synset or key in (n.replace("_", " ") for n in names):
            return synset
    return None


@dataclass(frozen=True)
class LabelSet:
    """Class names in label order, and how a data set's class name maps into them.

    Attributes
    ----------
    name : str
        ``modelnet40``, ``modelnet10``, ``shapenet55`` or ``own``.
    names : tuple of str
        The set's class list, one per label (``shape_names.txt``).
    """

    name: str
    names: tuple[str, ...]

    def labels(self, classes: Sequence[str]) -> dict[str, int]:
        """The label of each of the data set's ``classes`` in this set.

        Raises
        ------
        InvalidInputError
            Classes the set lacks, named, with the sets that would take them.
        """
        index = {n: i for i, n in enumerate(self.names)}
        if self.name == "shapenet55":
            found = {c: shapenet_synset(c) for c in classes}
            mapped = {c: index[s] for c, s in found.items() if s is not None}
        else:
            mapped = {c: index[c] for c in classes if c in index}
        missing = sorted(set(classes) - set(mapped))
        if missing:
            raise InvalidInputError(
                f"label_set_name={self.name!r} has no class {', '.join(map(repr, missing))}; "
                "use label_set_name='own' (the data set's own classes) or a set that has them"
            )
        return mapped


#: ``label_set_name`` (``--label-set``): the sets a pretrained network's labels follow.
LABEL_SETS = ("modelnet40", "modelnet10", "shapenet55", "own")


def label_set(name: str, own: Sequence[str]) -> LabelSet:
    """The label set ``name`` (``own``: the data set's classes ``own``, in their order).

    Raises
    ------
    InvalidInputError
        An unknown name.
    """
    sets = {
        "modelnet40": MODELNET40_CLASSES, "modelnet10": MODELNET10_CLASSES,
        "shapenet55": tuple(s for s, _ in SHAPENET55), "own": tuple(own),
    }  # fmt: skip
    if name not in sets:
        raise InvalidInputError(f"label_set_name={name!r}: give one of {', '.join(map(repr, LABEL_SETS))}")
    return LabelSet(name, sets[name])
