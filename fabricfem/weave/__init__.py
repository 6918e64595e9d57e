"""The woven fabric at the yarn scale: unit cells with yarn contact, periodic homogenization [Man2006, ch. 4]."""
